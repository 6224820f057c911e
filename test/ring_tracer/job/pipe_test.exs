defmodule RingTracer.Job.PipeTest do
  use ExUnit.Case, async: true

  alias RingTracer.Job.Pipe

  setup do
    # A stand-in grandchild pid of our own: entries are keyed by it.
    gc = spawn(fn -> :ok end)
    on_exit(fn -> Pipe.forget(gc) end)
    {:ok, gc: gc}
  end

  test "the grandchild claims first: the child cannot take the atom back", %{gc: gc} do
    assert Pipe.claim(gc, 7)
    refute Pipe.revoke(gc, 7)
    # Once the child has the pixels the entry is gone.
    Pipe.release(gc, 7)
    assert :ets.lookup(RingTracer.Names.pipe_table(), {gc, 7}) == []
  end

  test "the child revokes first: the grandchild skips the atom and cleans up", %{gc: gc} do
    assert Pipe.revoke(gc, 3)
    refute Pipe.claim(gc, 3)
    assert :ets.lookup(RingTracer.Names.pipe_table(), {gc, 3}) == []
  end

  test "claims are per grandchild and per atom", %{gc: gc} do
    other = spawn(fn -> :ok end)
    assert Pipe.claim(gc, 1)
    assert Pipe.claim(other, 1)
    assert Pipe.revoke(gc, 2)
    Pipe.forget(gc)
    Pipe.forget(other)
    assert :ets.match(RingTracer.Names.pipe_table(), {{gc, :"$1"}}) == []
  end

  test "the sweep removes the entries of dead grandchildren only", %{gc: gc} do
    dead = spawn(fn -> :ok end)
    ref = Process.monitor(dead)
    assert_receive {:DOWN, ^ref, _, _, _}
    alive = spawn(fn -> Process.sleep(:infinity) end)

    assert Pipe.revoke(dead, 1)
    assert Pipe.claim(alive, 1)
    Pipe.sweep()

    table = RingTracer.Names.pipe_table()
    assert :ets.lookup(table, {dead, 1}) == []
    assert :ets.lookup(table, {alive, 1}) == [{{alive, 1}}]
    Pipe.forget(alive)
    Pipe.forget(gc)
  end

  test "exactly one side wins when both race for the same atom" do
    for atom <- 1..200 do
      gc = spawn(fn -> :ok end)
      parent = self()
      racers = [&Pipe.claim/2, &Pipe.revoke/2]

      for f <- racers, do: spawn(fn -> send(parent, {:won, f.(gc, atom)}) end)
      wins = for _ <- racers, do: receive(do: ({:won, w} -> w))

      assert Enum.count(wins, & &1) == 1
      Pipe.forget(gc)
    end
  end
end
