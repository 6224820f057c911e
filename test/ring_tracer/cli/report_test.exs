defmodule RingTracer.CLI.ReportTest do
  use ExUnit.Case, async: true
  doctest RingTracer.CLI.Report

  alias RingTracer.CLI.Report

  test "a sequence's result (no pixels) gives the statistics block and its summary" do
    rays = %{RingTracer.Rays.zero() | eye: 10, eye_hits: 4, shadow: 3}

    result = %RingTracer.Result{
      width: 16,
      height: 12,
      pixels: nil,
      elapsed_us: 2_000_000,
      children: [
        %{
          index: 0,
          node: node(),
          own: 4,
          given: 1,
          received: 0,
          traced: 3,
          offers_sent: 2,
          offers_passed: 0,
          offers_consumed: 1
        }
      ],
      rays: rays,
      settings: nil
    }

    text = IO.iodata_to_binary(Report.statistics(result, 1_500))
    assert text =~ "parse 0.002 s, trace 2.000 s with 1 children\n"
    assert text =~ "rays: 13 (eye 10, 4 hit; reflected 0; refracted 0; shadow 3)"
    assert text =~ "  child 0: own 4, given 1, received 0, traced 3;"
    assert %{width: 16, rays: ^rays} = RingTracer.Report.Stats.summary(result)
  end

  test "a frame's line takes what it lacks as unknown, never crashes" do
    line =
      IO.iodata_to_binary(
        Report.frame(%{number: 3, elapsed_us: nil, atoms: nil, rays: nil}, "f.png")
      )

    assert line == "  frame 3: (? s in flight), ? atoms, ? rays, f.png\n"
  end
end
