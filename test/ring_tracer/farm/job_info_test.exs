defmodule RingTracer.Farm.JobInfoTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Farm.JobInfo

  alias RingTracer.Farm.JobInfo

  test "a ring started after half the frames were done counts them as done" do
    # 8 frames, 4 done before the ring started for the other 4; it has
    # traced half its atoms in 2 s.
    assert JobInfo.estimate(8, 4, {4, {50, 100}}, 2_000) == {0.75, 2_000}
  end

  test "progress never goes back below the frames done, nor beyond 1" do
    assert {0.5, _} = JobInfo.estimate(4, 2, {4, {1, 100}}, 10)
    assert {1.0, 0} = JobInfo.estimate(2, 2, {2, {120, 100}}, 10)
  end

  test "no time left before the ring has traced an atom, nor without a ring" do
    assert JobInfo.estimate(3, 0, {3, nil}, 500) == {0.0, nil}
    assert JobInfo.estimate(3, 3, nil, 0) == {1.0, nil}
  end
end
