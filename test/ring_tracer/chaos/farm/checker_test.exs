defmodule RingTracer.Chaos.Farm.CheckerTest do
  use ExUnit.Case, async: true

  alias RingTracer.Chaos.Farm.Checker
  alias RingTracer.Chaos.Farm.Checker.{Frame, JobEnd}

  doctest Checker

  defp done(i), do: %JobEnd{index: i, id: i + 1, state: :done}

  defp frame(i, n, got, expected \\ "h"),
    do: %Frame{index: i, number: n, got: got, expected: expected}

  test "every job done, every frame as rendered alone: passed, with the counts" do
    v =
      Checker.check([done(0), done(1)], [frame(0, 1, "h"), frame(1, 2, "h"), frame(1, 4, "h")], 0)

    assert %Checker{jobs: 2, done: 2, frames: 3, lost: 0, twice: 0, mismatches: 0, wrong: []} = v
    assert Checker.passed?(v)
  end

  test "a frame not stored is lost; one that differs is a mismatch; each names its job" do
    v =
      Checker.check([done(0), done(1)], [frame(0, 1, nil), frame(1, 2, "x"), frame(1, 3, "h")], 0)

    assert {v.lost, v.mismatches, v.wrong} == {1, 1, [0, 1]}
    refute Checker.passed?(v)
  end

  test "frames stored twice, or a job that did not end done, fail the soak" do
    refute Checker.passed?(Checker.check([done(0)], [frame(0, 1, "h")], 1))

    failed = %JobEnd{index: 3, id: 4, state: :failed, error: "boom"}
    v = Checker.check([done(0), failed], [frame(0, 1, "h")], 0)
    assert {v.done, v.wrong} == {1, [3]}
    refute Checker.passed?(v)
  end
end
