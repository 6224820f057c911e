defmodule RingTracer.Bench.TargetsTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Bench.Targets

  alias RingTracer.Bench.Targets

  @real ["4 equal", "4, one 4x slower", "8, speeds 1..8", "tetra, 4 equal", "teapot, 4 equal"]

  # A balance run's rows (scenario, strategy, makespan / ideal, messages per atom).
  @rows [
    {"4 equal", "static", 1.052, 1.125},
    {"4 equal", "master", 1.013, 2.125},
    {"4 equal", "ring", 1.023, 1.578},
    {"4 equal", "steal", 1.032, 1.469},
    {"4 equal", "ring/left", 1.025, 1.563},
    {"4 equal", "ring/interleaved", 1.016, 1.406},
    {"4 equal", "floor", 1.016, 0.000},
    {"4, one 4x slower", "static", 2.736, 1.125},
    {"4, one 4x slower", "master", 1.126, 2.125},
    {"4, one 4x slower", "ring", 1.063, 1.516},
    {"4, one 4x slower", "steal", 1.500, 1.781},
    {"4, one 4x slower", "ring/left", 1.064, 1.609},
    {"4, one 4x slower", "ring/interleaved", 1.059, 1.609},
    {"4, one 4x slower", "floor", 1.080, 0.000},
    {"8, speeds 1..8", "static", 2.088, 1.125},
    {"8, speeds 1..8", "master", 1.158, 2.125},
    {"8, speeds 1..8", "ring", 1.148, 2.008},
    {"8, speeds 1..8", "steal", 1.332, 2.516},
    {"8, speeds 1..8", "ring/left", 1.112, 2.172},
    {"8, speeds 1..8", "ring/interleaved", 1.095, 1.836},
    {"8, speeds 1..8", "floor", 1.098, 0.000},
    {"tetra, 4 equal", "static", 1.141, 1.125},
    {"tetra, 4 equal", "master", 1.021, 2.125},
    {"tetra, 4 equal", "ring", 1.080, 1.547},
    {"tetra, 4 equal", "steal", 1.169, 1.531},
    {"tetra, 4 equal", "ring/left", 1.069, 1.438},
    {"tetra, 4 equal", "ring/interleaved", 1.088, 1.375},
    {"tetra, 4 equal", "floor", 1.025, 0.000},
    {"teapot, 4 equal", "static", 1.045, 1.125},
    {"teapot, 4 equal", "master", 1.011, 2.125},
    {"teapot, 4 equal", "ring", 1.030, 1.531},
    {"teapot, 4 equal", "steal", 1.047, 1.531},
    {"teapot, 4 equal", "ring/left", 1.016, 1.453},
    {"teapot, 4 equal", "ring/interleaved", 1.028, 1.469},
    {"teapot, 4 equal", "floor", 1.008, 0.000},
    {"simulated N=64", "static", 2.539, 1.031},
    {"simulated N=64", "master", 1.073, 2.031},
    {"simulated N=64", "ring", 1.042, 1.760},
    {"simulated N=64", "steal", 1.093, 3.558},
    {"simulated N=64", "ring/left", 1.033, 1.788},
    {"simulated N=256", "static", 2.790, 1.031},
    {"simulated N=256", "master", 1.088, 2.031},
    {"simulated N=256", "ring", 1.069, 1.819},
    {"simulated N=256", "steal", 1.121, 9.553},
    {"simulated N=256", "ring/left", 1.067, 1.751},
    {"simulated N=1024", "static", 2.741, 1.031},
    {"simulated N=1024", "master", 1.112, 2.031},
    {"simulated N=1024", "ring", 1.110, 1.858},
    {"simulated N=1024", "steal", 1.278, 2.571},
    {"simulated N=1024", "ring/left", 1.101, 1.767}
  ]

  # What the targets print for those rows (a run from before adaptive
  # atoms: no `ring/split` rows, whose comparison says "no row").
  @lines [
    "ring <= 1.04 x ideal on 8 speeds: 1.148 MISSED",
    "ring <= 1.03 x ideal with one 4x slower: 1.063 MISSED",
    "ring within 0.02 of the floor: 4 equal 1.023 vs 1.016 ok; 4, one 4x slower 1.063 vs 1.080 ok; 8, speeds 1..8 1.148 vs 1.098 MISSED; tetra, 4 equal 1.080 vs 1.025 MISSED; teapot, 4 equal 1.030 vs 1.008 MISSED",
    "(not a target) the ring with adaptive atoms within 0.02 of the floor: 4 equal no row; 4, one 4x slower no row; 8, speeds 1..8 no row; tetra, 4 equal no row; teapot, 4 equal no row",
    "(not a target) the ring with offers to the left only <= 1.10 x ideal: 4 equal 1.025 yes; 4, one 4x slower 1.064 yes; 8, speeds 1..8 1.112 no; tetra, 4 equal 1.069 yes; teapot, 4 equal 1.016 yes",
    "(not a target) the ring on interleaved strips <= 1.10 x ideal: 4 equal 1.016 yes; 4, one 4x slower 1.059 yes; 8, speeds 1..8 1.095 yes; tetra, 4 equal 1.088 yes; teapot, 4 equal 1.028 yes",
    "ring <= 1.07 x ideal at N=1024: 1.110 MISSED",
    "static worse than ring (speeds or strips differ): 4, one 4x slower 2.736 vs 1.063 ok; 8, speeds 1..8 2.088 vs 1.148 ok; tetra, 4 equal 1.141 vs 1.080 ok; teapot, 4 equal 1.045 vs 1.030 ok",
    "ring fewer messages per atom than master: 4 equal 1.578 vs 2.125 ok; 4, one 4x slower 1.516 vs 2.125 ok; 8, speeds 1..8 2.008 vs 2.125 ok; tetra, 4 equal 1.547 vs 2.125 ok; teapot, 4 equal 1.531 vs 2.125 ok; simulated N=64 1.760 vs 2.031 ok; simulated N=256 1.819 vs 2.031 ok; simulated N=1024 1.858 vs 2.031 ok"
  ]

  defp rows,
    do:
      for(
        {s, st, ratio, msgs} <- @rows,
        do: %{scenario: s, strategy: st, ratio: ratio, msgs: msgs}
      )

  test "the targets print what the balance benchmark printed for the same rows" do
    assert Targets.lines(@real, rows()) == @lines

    assert Targets.report(@real, rows()) ==
             "\ntargets:\n" <> Enum.map_join(@lines, "\n", &("  " <> &1))
  end

  test "without the N=1024 rows (--quick) that target is not run" do
    quick = Enum.reject(rows(), &(&1.scenario in ["simulated N=256", "simulated N=1024"]))
    lines = Targets.lines(@real, quick)
    assert "ring <= 1.07 x ideal at N=1024: not run (--quick)" in lines
    assert List.last(lines) =~ ~r/simulated N=64 1.760 vs 2.031 ok$/
  end

  test "each target has a distinct name and a known check" do
    names = Enum.map(Targets.table(), & &1.name)
    assert names == Enum.uniq(names)

    for %{check: check} <- Targets.table() do
      assert match?({:at_most, _, _, _}, check) or
               match?({op, _, _, _} when op in [:below, :above], check) or
               match?({:within, _, _, _, margin} when is_number(margin), check)
    end
  end

  test "a missed target says MISSED, a comparison only says no" do
    rows = [
      %{scenario: "a", strategy: "ring", ratio: 1.2},
      %{scenario: "a", strategy: "ring/left", ratio: 1.2},
      %{scenario: "a", strategy: "floor", ratio: 1.1}
    ]

    [ring, left] =
      Enum.map([:ring_near_floor, :ring_left_makespan], fn name ->
        Enum.find(Targets.table(), &(&1.name == name))
      end)

    assert Targets.lines([ring, left], ["a"], rows) == [
             "ring within 0.02 of the floor: a 1.200 vs 1.100 MISSED",
             "(not a target) the ring with offers to the left only <= 1.10 x ideal: a 1.200 no"
           ]
  end
end
