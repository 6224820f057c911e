defmodule RingTracer.Preview.PacingTest do
  use ExUnit.Case, async: true

  alias RingTracer.Preview.Pacing

  doctest Pacing

  test "the thread's CPU clock advances with work done on it, and work is never more than wall time" do
    before = System.monotonic_time(:microsecond)
    mark = Pacing.start()
    # Work until the thread's own clock shows 5 ms (a deadline of 10 s of
    # wall time, whatever the machine's load).
    spin = fn spin, n ->
      us = Pacing.work_us(mark)

      cond do
        us >= 5_000 -> us
        System.monotonic_time(:microsecond) - before > 10_000_000 -> flunk("no CPU time")
        true -> spin.(spin, n + :erlang.phash2(n))
      end
    end

    work = spin.(spin, 1)
    wall = System.monotonic_time(:microsecond) - before
    assert work >= 5_000
    assert work <= wall
  end
end
