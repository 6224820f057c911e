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
    assert :ets.match(RingTracer.Names.pipe_table(), {{gc, :"$1"}, :_}) == []
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
    assert :ets.lookup(table, {alive, 1}) == [{{alive, 1}, 1}]
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

  describe "cutting an atom traced in parts" do
    test "the cut takes the parts not started; the grandchild stops there", %{gc: gc} do
      assert Pipe.claim(gc, 4)
      assert Pipe.next(gc, 4)
      assert Pipe.started(gc, 4) == 2
      # Parts 0 and 1 are the grandchild's, 2 to 7 the child's.
      assert Pipe.cut(gc, 4, 8) == {:ok, 2}
      refute Pipe.next(gc, 4)
      assert :ets.lookup(RingTracer.Names.pipe_table(), {gc, 4}) == []
    end

    test "nothing to cut: every part started, the atom not started, or failed", %{gc: gc} do
      assert Pipe.claim(gc, 1)
      assert Pipe.next(gc, 1)
      assert Pipe.cut(gc, 1, 2) == :none
      assert Pipe.cut(gc, 2, 4) == :none
      # No entry is made by a cut: the grandchild can still claim atom 2.
      assert Pipe.claim(gc, 2)
      assert Pipe.fail(gc, 2) == nil
      assert Pipe.cut(gc, 2, 4) == :none
      assert Pipe.revoke(gc, 3)
      assert Pipe.cut(gc, 3, 4) == :none
    end

    test "a grandchild failing after a cut learns which parts were left to it", %{gc: gc} do
      assert Pipe.claim(gc, 6)
      assert Pipe.cut(gc, 6, 4) == {:ok, 1}
      assert Pipe.fail(gc, 6) == 1
      assert :ets.lookup(RingTracer.Names.pipe_table(), {gc, 6}) == []
    end

    test "each part goes to exactly one side when the cut races the grandchild" do
      for round <- 1..200 do
        gc = spawn(fn -> :ok end)
        parent = self()
        n = 8
        true = Pipe.claim(gc, round)

        spawn(fn ->
          taken =
            Enum.reduce_while(1..(n - 1), 1, fn _, k ->
              if Pipe.next(gc, round), do: {:cont, k + 1}, else: {:halt, k}
            end)

          send(parent, {:grandchild, taken})
        end)

        spawn(fn -> send(parent, {:child, Pipe.cut(gc, round, n)}) end)
        assert_receive {:grandchild, taken}
        assert_receive {:child, cut}

        case cut do
          {:ok, from} -> assert from == taken
          :none -> assert taken == n
        end

        Pipe.forget(gc)
      end
    end
  end
end
