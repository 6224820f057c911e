defmodule RingTracer.Chaos.PlanTest do
  use ExUnit.Case, async: true

  alias RingTracer.Chaos.Plan

  doctest Plan

  @scenes ["a.nff", "b.toml", "c.nff"]

  test "the plan is a function of the seed" do
    plan = Plan.new(seed: 5, jobs: 50, scenes: @scenes)
    assert plan == Plan.new(seed: 5, jobs: 50, scenes: @scenes)
    refute plan == Plan.new(seed: 6, jobs: 50, scenes: @scenes)
    assert Enum.map(plan, & &1.index) == Enum.to_list(0..49)
  end

  test "jobs and faults stay within the ranges asked for" do
    plan =
      Plan.new(
        seed: 9,
        jobs: 200,
        scenes: @scenes,
        strategies: [:ring, :steal],
        children: 2..4,
        atoms: 3..5,
        slowdown: 10..20,
        faults_per_job: 3
      )

    for job <- plan do
      assert job.scene in @scenes
      assert job.strategy in [:ring, :steal]
      assert job.children in 2..4 and job.atoms in 3..5
      assert length(job.speeds) == job.children and Enum.all?(job.speeds, &(&1 in 10..20))
      assert length(job.faults) == 3
      assert Enum.map(job.faults, & &1.at) == Enum.sort(Enum.map(job.faults, & &1.at))
      assert Enum.all?(job.faults, &(&1.at in 1..(job.children * job.atoms - 1)))
      assert Enum.all?(job.faults, &(&1.kind in Plan.kinds() and &1.pick >= 0))
    end

    kinds = plan |> Enum.flat_map(& &1.faults) |> Enum.frequencies_by(& &1.kind)
    assert Map.keys(kinds) |> Enum.sort() == Enum.sort(Plan.kinds())
    # The default weights draw process kills three times as often as node faults.
    assert kinds.grandchild > kinds.node and kinds.child > kinds.freeze
  end

  test "a weight of 0 leaves a kind out; no faults per job plans none" do
    plan = Plan.new(seed: 2, jobs: 100, scenes: @scenes, weights: [child: 1, node: 0])
    assert plan |> Enum.flat_map(& &1.faults) |> Enum.all?(&(&1.kind == :child))

    assert Plan.new(seed: 2, jobs: 10, scenes: @scenes, faults_per_job: 0)
           |> Enum.all?(&(&1.faults == []))

    assert Plan.new(seed: 2, jobs: 0, scenes: @scenes) == []
  end
end
