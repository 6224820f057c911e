defmodule Mix.Tasks.RingTracer.ChaosTest do
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  alias Mix.Tasks.RingTracer.Chaos, as: Task

  describe "a short soak" do
    @describetag :distributed
    @describetag timeout: 180_000

    test "kills and freezes at random moments, and every image is the clean render's" do
      # The default soak's first twelve jobs, two at once on two peer nodes, two
      # faults each: every kind of fault (see below).
      argv = ~w(--seed 1 --jobs 12 --concurrency 2 --nodes 2 --faults-per-job 2
                --liveness 1000 --width 64 --height 48)

      output = capture_io(fn -> Task.run(argv) end)

      assert output =~ ~r/jobs run\s+12\n/
      assert output =~ ~r/atoms lost\s+0 of \d+\n/
      assert output =~ ~r/atoms traced twice\s+0\n/
      assert output =~ ~r/images differing \(atoms\)\s+0 \(0\)\n/
      assert output =~ ~r/parents and children left on this node\s+0\n/
      refute output =~ "jobs that went wrong"

      [injected] = Regex.run(~r/faults injected\s+(\d+)\n/, output, capture: :all_but_first)
      [skipped] = Regex.run(~r/faults skipped[^\n]*?(\d+)\n/, output, capture: :all_but_first)
      assert String.to_integer(injected) + String.to_integer(skipped) == 24
      assert String.to_integer(injected) > 0
      # No peer node of the soak outlives it.
      assert RingTracer.Test.Wait.eventually(fn -> chaos_nodes() == [] end)
    end
  end

  test "the plan of the short soak's seed has every kind of fault" do
    kinds =
      RingTracer.Chaos.Plan.new(seed: 1, jobs: 12, scenes: RingTracer.Chaos.default_scenes())
      |> Enum.flat_map(& &1.faults)
      |> Enum.map(& &1.kind)
      |> Enum.uniq()
      |> Enum.sort()

    assert kinds == Enum.sort(RingTracer.Chaos.Plan.kinds())
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

    assert Task.parse(~w(--seed 4 --scenes a.nff,b.nff --only 2,5 --weights node=2)) == [
             seed: 4,
             scenes: ["a.nff", "b.nff"],
             only: [2, 5],
             weights: [grandchild: 3, child: 3, node: 2, freeze: 1]
           ]
  end

  test "a missing scene, or jobs render/2 would refuse, stop the soak before any job" do
    Mix.Task.run("app.start")

    assert_raise Mix.Error, ~r/no scene nowhere\.nff/, fn ->
      Task.run(~w(--scenes nowhere.nff))
    end

    assert_raise Mix.Error, ~r/:speeds/, fn -> Task.run(~w(--slowdown 10-5000)) end
  end

  defp chaos_nodes,
    do: Enum.filter(Node.list(), &String.starts_with?(Atom.to_string(&1), "chaos"))
end
