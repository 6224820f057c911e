defmodule RingTracer.BenchTest do
  # not async: the floor test checks that no process it started outlives it
  use ExUnit.Case, async: false
  doctest RingTracer.Bench
  doctest RingTracer.Bench.PovRay
  doctest RingTracer.Bench.Balance

  alias RingTracer.Bench.Balance
  alias RingTracer.TestScenes

  test "median_result takes the run in the middle by makespan over ideal" do
    runs = [
      %{elapsed_us: 300, ideal_us: 100},
      %{elapsed_us: 110, ideal_us: 100},
      %{elapsed_us: 150, ideal_us: 100}
    ]

    {:ok, agent} = Agent.start_link(fn -> runs end)
    next = fn -> {:ok, Agent.get_and_update(agent, fn [r | rest] -> {r, rest} end)} end
    assert RingTracer.Bench.median_result(3, next) == %{elapsed_us: 150, ideal_us: 100}
  end

  test "a balance row from a job's result" do
    {:ok, result} = RingTracer.simulate(children: 2, atoms: 2, costs: 1000)
    row = Balance.row("simulated N=2", "ring", result)
    assert %{scenario: "simulated N=2", strategy: "ring", msgs: msgs, bytes: bytes} = row
    assert row.ratio == result.elapsed_us / result.ideal_us
    assert msgs > 0 and bytes > 0
    assert row.idle_pct >= 0 and row.idle_pct <= 100
    assert length(Balance.cells(row)) == 8
    # where the makespan went at the end: the last atom ended within it
    assert row.tail.last_us > 0 and row.tail.last_us <= result.elapsed_us
    assert 0 <= row.tail.tail_us and row.tail.tail_us <= row.tail.first_idle_us
    assert row.tail.last_speed == 1
  end

  test "the cost of one dirty kernel call, as the kernel benchmark prints it" do
    us = RingTracer.Bench.Kernel.nif_call_us(TestScenes.path("balls_s1.nff"))
    assert is_float(us) and us > 0
  end

  test "where a job's fixed cost goes, part by part" do
    parts = RingTracer.Bench.Kernel.fixed_costs(TestScenes.path("balls_s1.nff"), 2, 2, 1)

    assert Enum.map(parts, &elem(&1, 0)) ==
             ["start-up", "per atom", "atoms", "ring protocol", "work preview", "end"]

    assert Enum.all?(parts, fn {_, us} -> is_number(us) end)
    assert {_, start} = List.keyfind(parts, "start-up", 0)
    assert start >= 0
  end

  test "the floor traces every atom through real grandchildren, and leaves none behind" do
    scene = RingTracer.Scene.load!(TestScenes.path("balls_s1.nff"))
    before = Process.list()

    {:ok, %{elapsed_us: elapsed, ideal_us: ideal, tail: tail}} =
      Balance.floor(scene, 32, 2, 3, [1, 2])

    assert ideal > 0 and elapsed > 0
    assert tail.last_us > 0 and tail.last_us <= elapsed and tail.last_speed in [1, 2]
    assert tail.gives_late == 0 and tail.offer_us == nil
    # a speed of 2 makes the floor's capacity 1.5 atoms at once, so its ideal
    # is the work over 1.5: the makespan cannot beat it by much
    assert elapsed >= ideal * 0.5

    assert RingTracer.Test.Wait.eventually(fn ->
             Enum.all?(Process.list() -- before, &(not Process.alive?(&1)))
           end)
  end
end
