defmodule RingTracer.Job.SlowdownTest do
  use ExUnit.Case, async: false

  alias RingTracer.Job.Slowdown

  doctest Slowdown

  test "a child of speed 1 does not wait" do
    {us, slowdown} = :timer.tc(fn -> Slowdown.wait(Slowdown.new(1), 50_000) end)
    assert us < 5_000
    assert slowdown.balance == 0
  end

  test "over many atoms a child waits (speed - 1) x its trace time, late timers included" do
    # 40 atoms of 1.5 ms at speed 2 owe 60 ms. Sleeping round(1.5) = 2 ms
    # per atom, as the first emulation did, waited 80 ms, more with late
    # timers; the balance keeps the total within one sleep's error.
    {us, slowdown} =
      :timer.tc(fn ->
        Enum.reduce(1..40, Slowdown.new(2), fn _, s -> Slowdown.wait(s, 1_500) end)
      end)

    assert_in_delta us, 60_000, 5_000
    assert slowdown.balance in -5_000..500
  end

  test "what a late sleep overran comes off the next one" do
    late = %{Slowdown.new(4) | balance: -2_000}
    {us, slowdown} = :timer.tc(fn -> Slowdown.wait(late, 1_000) end)
    assert_in_delta us, 1_000, 1_500
    assert slowdown.balance in -3_000..500
  end
end
