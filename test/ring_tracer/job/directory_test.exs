defmodule RingTracer.Job.DirectoryTest do
  use ExUnit.Case, async: false

  import RingTracer.Test.Wait

  alias RingTracer.Job.Directory

  defp published?(id) do
    Directory.sibling(id, 0)
    true
  rescue
    ArgumentError -> false
  end

  test "a job's ring is published on a node until its parent ends" do
    id = make_ref()
    parent = spawn(fn -> receive(do: (:stop -> :ok)) end)
    pids = {self(), parent, self()}

    assert :ok = Directory.publish(node(), id, parent, pids)
    assert :ok = Directory.await(id, 3, 1_000)
    assert Directory.sibling(id, 1) == parent
    assert Directory.sibling(id, 2) == self()
    assert Directory.jobs() >= 1

    send(parent, :stop)
    assert eventually(fn -> not published?(id) end)
  end

  test "a child waits for its ring until it is published, and no longer than its deadline" do
    id = make_ref()
    parent = spawn(fn -> receive(do: (:stop -> :ok)) end)
    waiter = Task.async(fn -> Directory.await(id, 2, 10_000) end)
    # the waiter has asked (its call is in the directory's queue) before the ring comes
    assert eventually(fn -> Map.has_key?(:sys.get_state(Directory).waiting, id) end)
    assert :ok = Directory.publish(node(), id, parent, {self(), parent})
    assert :ok = Task.await(waiter, 5_000)

    # a larger ring (grown) is awaited by its size
    assert {:error, :timeout} = Directory.await(id, 3, 50)
    assert :ok = Directory.publish(node(), id, parent, {self(), parent, self()})
    assert :ok = Directory.await(id, 3, 1_000)

    # a ring that never comes: the deadline, not a hang
    assert {:error, :timeout} = Directory.await(make_ref(), 1, 50)
    send(parent, :stop)
  end

  test "publishing on a node that cannot be reached neither raises nor waits" do
    assert :ok = Directory.publish(:nobody@nowhere, make_ref(), self(), {self()})
  end

  # The size of one child's state, in words, once it knows its ring, while
  # every child of a ring of `n` is tracing its one atom (simulated, of three
  # seconds: children trace from their start, and the last of 2,048 may
  # start a second or two after the first on a loaded machine).
  defp child_words(n) do
    task = Task.async(fn -> RingTracer.simulate(children: n, atoms: 1, costs: 3_000_000) end)

    assert eventually(
             fn -> length(RingTracer.TestScenes.children()) == n end,
             10_000
           )

    child = Enum.find(RingTracer.TestScenes.children(), &(:sys.get_state(&1).index == 1))
    assert eventually(fn -> :sys.get_state(child).left != nil end)
    words = :erts_debug.flat_size(:sys.get_state(child))
    assert {:ok, _} = Task.await(task, 30_000)
    words
  end

  test "a child's memory does not grow with the ring: it holds no copy of it" do
    small = child_words(4)
    large = child_words(2_048)
    # A copy of the ring would be 2,048 words more (one per pid) at least.
    assert large - small < 64, "4 children: #{small} words, 2048 children: #{large}"
  end
end
