defmodule RingTracer.Bench.PreviewTest do
  use ExUnit.Case, async: false
  doctest RingTracer.Bench.Preview

  import ExUnit.CaptureIO

  alias RingTracer.Bench.Preview

  test "the interval is the bootstrap's: the same values give the same bounds, and they hold the median" do
    values = for i <- 1..41, do: 1.0 + :math.sin(i) / 50
    {lo, hi} = Preview.median_ci(values, 2_000)
    assert {lo, hi} == Preview.median_ci(values, 2_000)
    sorted = Enum.sort(values)
    assert lo <= Enum.at(sorted, 20) and Enum.at(sorted, 20) <= hi
    assert lo >= hd(sorted) and hi <= List.last(sorted)
    # Far narrower than the values' spread.
    assert hi - lo < (List.last(sorted) - hd(sorted)) / 2
    assert Preview.median_ci(List.duplicate(1.5, 9), 100) == {1.5, 1.5}
  end

  for viewer <- [:curl, :httpc] do
    test "prints the row and the target's verdict (viewer #{viewer})" do
      viewer = unquote(viewer)

      if viewer == :curl and System.find_executable("curl") == nil do
        IO.puts("no curl here: the curl viewer is not checked")
      else
        out =
          capture_io(fn ->
            row =
              Preview.measure(
                pairs: 3,
                width: 32,
                height: 32,
                children: 2,
                atoms: 2,
                scene: "priv/scenes/tetra_s1.nff",
                viewer: viewer
              )

            send(self(), {:row, row})
          end)

        assert_received {:row, row}
        assert row.pairs == 3 and row.viewer == viewer
        {lo, hi} = row.ci
        assert lo <= row.pair_ratio and row.pair_ratio <= hi
        assert out =~ "preview: 32x32 tetra_s1.nff, 2 children x 2 atoms, 3 pairs"
        assert out =~ ~r/median of the pairs' ratios \d+\.\d{3}x, 95% CI \d+\.\d{3}-\d+\.\d{3}/
        assert out =~ "VM CPU time during the job: median"

        assert out =~
                 ~r/targets:\n  a preview and one viewer add at most 3% .*: \d+\.\d{3} (ok|MISSED)/

        assert out =~ " ok" == row.met
      end
    end
  end
end
