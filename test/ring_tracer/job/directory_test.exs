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

    assert :ok = Directory.publish(node(), id, parent, pids, 1_000)
    assert Directory.sibling(id, 1) == parent
    assert Directory.sibling(id, 2) == self()
    assert Directory.jobs() >= 1

    send(parent, :stop)
    assert eventually(fn -> not published?(id) end)
  end

  test "publishing on a node that does not answer is an error, not a hang" do
    assert {:error, _} = Directory.publish(:nobody@nowhere, make_ref(), self(), {self()}, 100)
  end

  # The size of one child's state, in words, while every child of a ring of
  # `n` is tracing its first atom (simulated atoms of half a second).
  defp child_words(n) do
    task = Task.async(fn -> RingTracer.simulate(children: n, atoms: 2, costs: 500_000) end)

    assert eventually(
             fn -> length(RingTracer.TestScenes.children()) == n end,
             10_000
           )

    child = Enum.find(RingTracer.TestScenes.children(), &(:sys.get_state(&1).index == 1))
    assert eventually(fn -> :sys.get_state(child).status == :working end)
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
