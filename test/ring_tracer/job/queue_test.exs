defmodule RingTracer.Job.QueueTest do
  use ExUnit.Case, async: true

  alias RingTracer.Job.Queue

  test "front to trace, back to give, in the order a list had them" do
    q = Queue.new([1, 2, 3, 4, 5])
    assert {Queue.size(q), Queue.last(q)} == {5, 5}
    assert {1, q} = Queue.next(q)
    assert {[4, 5], q} = Queue.take_last(q, 2)
    assert Queue.to_list(q) == [2, 3]
    assert {[2, 3], empty} = Queue.take_last(q, 10)
    assert {Queue.size(empty), Queue.last(empty), Queue.next(empty)} == {0, nil, :empty}
    q = q |> Queue.replace_last({3, 0, 1, 2}) |> Queue.push_front(0)
    assert Queue.to_list(q) == [0, 2, {3, 0, 1, 2}]
    assert Queue.size(q) == 3
  end

  test "appending leaves out atoms held in the pipe or already queued" do
    q = Queue.new([1, 2, 3])
    {q, new} = Queue.append(q, [3, 4, 7, 5], MapSet.new([7]))
    assert new == [4, 5]
    assert {Queue.to_list(q), Queue.size(q)} == {[1, 2, 3, 4, 5], 5}
    assert {^q, []} = Queue.append(q, [], MapSet.new())
  end

  # What a child does once per atom (take the next, tell its strategy how
  # many are queued and the share of the last) must not grow with the queue:
  # it did with a list (length/1 and List.last/1 each walk it), which made a
  # child of n atoms cost O(n^2). Counted in reductions, not time.
  test "the per-atom operations cost the same on a queue of a million atoms as of a thousand" do
    per_atom = fn n ->
      q = Queue.new(Enum.to_list(1..n))

      reductions(fn ->
        Enum.reduce(1..500, q, fn _, q ->
          _ = {Queue.size(q), Queue.last(q)}
          {_, q} = Queue.next(q)
          q
        end)
      end)
    end

    small = per_atom.(1_000)
    big = per_atom.(1_000_000)

    assert big <= small * 2 + 1_000,
           "#{big} reductions for 500 atoms of a million, #{small} of a thousand"
  end

  defp reductions(fun) do
    {:reductions, before} = Process.info(self(), :reductions)
    fun.()
    {:reductions, later} = Process.info(self(), :reductions)
    later - before
  end
end
