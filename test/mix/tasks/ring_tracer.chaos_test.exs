defmodule Mix.Tasks.RingTracer.ChaosTest do
  use ExUnit.Case, async: false
  # `bin/ringtracer test` runs it in a second test VM (docs/testing.md).
  @moduletag :second_vm

  import ExUnit.CaptureIO

  alias Mix.Tasks.RingTracer.Chaos, as: Task

  describe "a short soak" do
    @describetag :distributed
    @describetag timeout: 180_000

    test "kills and freezes at random moments, and every image and frame is the clean render's" do
      # The default soak's first twelve jobs, two at once on two peer nodes, two
      # faults each, with more sequences than by default (35% of jobs, not 20%):
      # three, which meet every kind of fault between them (see below).
      argv = ~w(--seed 1 --jobs 12 --concurrency 2 --nodes 2 --faults-per-job 2
                --liveness 1000 --width 64 --height 48 --sequences 35)

      frames = short_soak_plan() |> Enum.flat_map(&(&1.frames || [])) |> length()
      output = capture_io(fn -> Task.run(argv) end)

      assert output =~ ~r/jobs run\s+12\n/
      assert output =~ ~r/atoms lost\s+0 of \d+\n/
      assert output =~ ~r/atoms traced twice\s+0\n/
      assert output =~ ~r/images differing \(atoms\)\s+0 \(0\)\n/
      assert output =~ ~r/parents and children left on this node\s+0\n/
      # Every frame asked for came once, each that frame's clean render.
      assert output =~ ~r/frames lost\s+0 of #{frames}\n/
      assert output =~ ~r/frames delivered twice\s+0\n/
      assert output =~ ~r/frames differing \(atoms\)\s+0 \(0\)\n/
      refute output =~ "jobs that went wrong"

      [sequences, in_sequences] =
        Regex.run(~r/sequences run \(faults injected in them\)\s+(\d+) \((\d+)\)\n/, output,
          capture: :all_but_first
        )

      assert String.to_integer(sequences) == 3
      assert String.to_integer(in_sequences) > 0

      [injected] = Regex.run(~r/faults injected\s+(\d+)\n/, output, capture: :all_but_first)
      [skipped] = Regex.run(~r/faults skipped[^\n]*?(\d+)\n/, output, capture: :all_but_first)
      assert String.to_integer(injected) + String.to_integer(skipped) == 24
      assert String.to_integer(injected) > 0
      # No peer node of the soak outlives it.
      assert RingTracer.Test.Wait.eventually(fn -> chaos_nodes() == [] end)
    end
  end

  test "the plan of the short soak's seed has every kind of fault, in its sequences too" do
    plan = short_soak_plan()

    kinds = fn jobs ->
      jobs |> Enum.flat_map(& &1.faults) |> Enum.map(& &1.kind) |> Enum.uniq()
    end

    assert Enum.sort(kinds.(plan)) == Enum.sort(RingTracer.Chaos.Plan.kinds())
    sequences = Enum.filter(plan, & &1.frames)
    assert length(sequences) == 3
    assert Enum.sort(kinds.(sequences)) == Enum.sort(RingTracer.Chaos.Plan.kinds())
  end

  # The plan of the short soak above, with the soak's defaults.
  defp short_soak_plan do
    defaults = RingTracer.Chaos.defaults()

    RingTracer.Chaos.Plan.new(
      seed: 1,
      jobs: 12,
      scenes: defaults[:scenes],
      sequences: 35,
      sequence_scene: defaults[:sequence_scene],
      scene_frames: 48,
      frames: defaults[:frames],
      window: defaults[:window]
    )
  end

  test "--help prints the usage and starts nothing" do
    for flag <- ["--help", "-h"] do
      output = capture_io(fn -> assert Task.run([flag, "--jobs", "0"]) == :ok end)
      assert output =~ "mix ring_tracer.chaos [--seed 1]"
      assert output =~ "--faults-per-job"
      refute output =~ ~r/jobs run\s+\d/
    end
  end

  test "options are checked before anything starts" do
    assert_raise Mix.Error, ~r/unknown strategy spiral/, fn ->
      Task.parse(~w(--strategies ring,spiral))
    end

    assert_raise Mix.Error, ~r/--weights/, fn -> Task.parse(~w(--weights child=x)) end

    assert_raise Mix.Error, ~r/no fault kind/, fn ->
      Task.parse(~w(--weights grandchild=0,child=0,node=0,freeze=0))
    end

    assert_raise Mix.Error, ~r/--jobs must be positive/, fn -> Task.parse(~w(--jobs 0)) end
    assert_raise Mix.Error, ~r/unexpected arguments/, fn -> Task.parse(~w(extra)) end

    assert_raise Mix.Error, ~r/--children takes N or MIN-MAX/, fn ->
      Task.parse(~w(--children 6-3))
    end

    assert Task.parse(~w(--children 8-16 --atoms 4 --slowdown 1-1)) == [
             children: 8..16,
             atoms: 4..4,
             slowdown: 1..1
           ]

    assert_raise Mix.Error, ~r/--sequences is a percentage from 0 to 100/, fn ->
      Task.parse(~w(--sequences 120))
    end

    assert_raise Mix.Error, ~r/--window takes N or MIN-MAX/, fn -> Task.parse(~w(--window 0)) end

    assert Task.parse(~w(--sequences 0 --sequence-scene fly.toml --frames 3-6 --window 2)) == [
             sequences: 0,
             sequence_scene: "fly.toml",
             frames: 3..6,
             window: 2..2
           ]

    assert Task.parse(~w(--seed 4 --scenes a.nff,b.nff --only 2,5 --weights node=2)) == [
             seed: 4,
             scenes: ["a.nff", "b.nff"],
             only: [2, 5],
             weights: [grandchild: 3, child: 3, node: 2, freeze: 1]
           ]
  end

  test "--farm's options are checked before anything starts" do
    assert_raise Mix.Error, ~r/--workers needs --farm/, fn -> Task.run(~w(--workers 2)) end

    assert_raise Mix.Error, ~r/--strategies is not an option of --farm/, fn ->
      Task.run(~w(--farm --strategies ring))
    end

    assert_raise Mix.Error, ~r/--speed must be positive/, fn -> Task.parse(~w(--speed 0)) end

    assert Task.parse(~w(--farm --seed 42 --jobs 60 --workers 4 --duration 9000)) ==
             [farm: true, seed: 42, jobs: 60, workers: 4, duration: 9000]

    output = capture_io(fn -> Task.run(["--help"]) end)
    assert output =~ "mix ring_tracer.chaos --farm"
  end

  test "a missing scene, or jobs render/2 would refuse, stop the soak before any job" do
    Mix.Task.run("app.start")

    assert_raise Mix.Error, ~r/no scene nowhere\.nff/, fn ->
      Task.run(~w(--scenes nowhere.nff))
    end

    assert_raise Mix.Error, ~r/:speeds/, fn -> Task.run(~w(--slowdown 10-5000)) end

    assert_raise Mix.Error, ~r/no scene nowhere\.toml/, fn ->
      Task.run(~w(--sequence-scene nowhere.toml))
    end

    # A still has one frame: no sequence of two.
    assert_raise Mix.Error, ~r/at least 2 frames asked, but whitted\.toml has 1/, fn ->
      Task.run(~w(--sequence-scene whitted.toml))
    end

    assert_raise Mix.Error, ~r/:window must be an integer from 1 to 64/, fn ->
      Task.run(~w(--window 2-80))
    end
  end

  defp chaos_nodes,
    do: Enum.filter(Node.list(), &String.starts_with?(Atom.to_string(&1), "chaos"))
end
