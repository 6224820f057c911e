defmodule RingTracer.Job.SlowdownTest do
  # The rules, with the sleeps simulated (how late a timer fires is the
  # machine's business, not a test's): deterministic under any load.
  use ExUnit.Case, async: true

  alias RingTracer.Job.Slowdown

  doctest Slowdown

  # Runs `atoms` atoms of `trace_us` through the rules, each sleep lasting
  # what was asked plus `late.(i)` microseconds; returns the time slept and
  # the last state.
  defp simulate(slowdown, atoms, trace_us, late) do
    Enum.reduce(1..atoms, {0, slowdown}, fn i, {slept, s} ->
      case Slowdown.plan(s, trace_us) do
        {0, owed} ->
          {slept, Slowdown.settle(s, owed, 0)}

        {ms, owed} ->
          took = ms * 1000 + late.(i)
          {slept + took, Slowdown.settle(s, owed, took)}
      end
    end)
  end

  test "a child of speed 1 does not wait" do
    assert {0, %Slowdown{balance: 0}} = simulate(Slowdown.new(1), 40, 50_000, fn _ -> 0 end)
  end

  test "over many atoms a child waits (speed - 1) x its trace time, late timers included" do
    # 40 atoms of 1.5 ms at speed 2 owe 60 ms. Sleeping round(1.5) = 2 ms
    # per atom, as the first emulation did, waited 80 ms, more with late
    # timers; the balance keeps the total within one sleep's error, however
    # late the timers (here 0 to 2.4 ms, as measured on a busy machine).
    for late <- [fn _ -> 0 end, fn i -> rem(i * 937, 2_401) end, fn _ -> 2_400 end] do
      {slept, s} = simulate(Slowdown.new(2), 40, 1_500, late)
      assert slept == 60_000 - s.balance
      assert s.balance in -2_400..500
    end
  end

  test "what a late sleep overran comes off the next one" do
    late = %{Slowdown.new(4) | balance: -2_000}
    # 3 ms owed for this atom, 2 ms overran last time: 1 ms now.
    assert Slowdown.plan(late, 1_000) == {1, 1_000}
    # Overrun by more than is owed: no sleep, and the debt carries on.
    assert Slowdown.plan(%{late | balance: -5_000}, 1_000) == {0, -2_000}
  end

  test "the real wait sleeps and keeps what it did not (or overran) in its balance" do
    {outer, s} = :timer.tc(fn -> Slowdown.wait(Slowdown.new(3), 1_000) end)
    # 2 ms owed; the balance is what is still owed after the sleep it timed,
    # which lies within the time measured around it.
    assert s.balance < 2_000
    assert s.balance >= 2_000 - outer
  end
end
