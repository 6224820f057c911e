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

  describe "sequences" do
    @sequence [
      sequence_scene: "orbit.toml",
      scene_frames: 48,
      frames: 2..5,
      window: 1..3
    ]

    test "are a function of the seed, within the ranges asked for" do
      plan = Plan.new([seed: 4, jobs: 200, scenes: @scenes, sequences: 30] ++ @sequence)
      assert plan == Plan.new([seed: 4, jobs: 200, scenes: @scenes, sequences: 30] ++ @sequence)
      refute plan == Plan.new([seed: 5, jobs: 200, scenes: @scenes, sequences: 30] ++ @sequence)

      {sequences, images} = Enum.split_with(plan, & &1.frames)
      # 30% of 200 jobs: about 60 (the draws are fixed by the seed).
      assert length(sequences) in 40..80

      for job <- sequences do
        assert job.scene == "orbit.toml"
        assert length(job.frames) in 2..5 and Enum.all?(job.frames, &(&1 in 1..48))
        assert job.frames == job.frames |> Enum.uniq() |> Enum.sort()
        assert job.window in 1..3
        # Faults are due at atom counts over every frame of the sequence.
        total = job.children * job.atoms * length(job.frames)
        assert Enum.all?(job.faults, &(&1.at in 1..(total - 1)))
        assert length(job.faults) == 2
      end

      assert Enum.all?(images, &(&1.scene in @scenes and &1.frames == nil and &1.window == nil))
      # Faults land past a sequence's first frame too, and frames are drawn
      # from the whole scene, not only its start.
      assert Enum.any?(sequences, fn job ->
               Enum.any?(job.faults, &(&1.at > job.children * job.atoms))
             end)

      assert sequences |> Enum.flat_map(& &1.frames) |> Enum.max() > 40

      assert sequences |> Enum.map(&length(&1.frames)) |> Enum.uniq() |> Enum.sort() == [
               2,
               3,
               4,
               5
             ]

      assert sequences |> Enum.map(& &1.window) |> Enum.uniq() |> Enum.sort() == [1, 2, 3]
    end

    test "turning them on changes no other job's draws" do
      images = Plan.new(seed: 8, jobs: 100, scenes: @scenes)
      mixed = Plan.new([seed: 8, jobs: 100, scenes: @scenes, sequences: 40] ++ @sequence)
      assert Enum.any?(mixed, & &1.frames)

      for {image, job} <- Enum.zip(images, mixed) do
        if job.frames do
          # The same ring, speeds and fault kinds and picks; the counts differ.
          assert Map.take(job, [:strategy, :children, :atoms, :speeds]) ==
                   Map.take(image, [:strategy, :children, :atoms, :speeds])

          kinds = fn job -> job.faults |> Enum.map(&{&1.kind, &1.pick}) |> Enum.sort() end
          assert kinds.(job) == kinds.(image)
        else
          assert job == image
        end
      end
    end

    test "every job, or none; a short scene bounds the frames" do
      all = Plan.new([seed: 3, jobs: 20, scenes: @scenes, sequences: 100] ++ @sequence)
      assert Enum.all?(all, & &1.frames)

      assert Plan.new([seed: 3, jobs: 20, scenes: @scenes, sequences: 0] ++ @sequence) ==
               Plan.new(seed: 3, jobs: 20, scenes: @scenes)

      short =
        Plan.new(
          [seed: 3, jobs: 20, scenes: @scenes, sequences: 100] ++
            Keyword.merge(@sequence, scene_frames: 3)
        )

      assert Enum.all?(short, &(&1.frames in [[1, 2], [1, 3], [2, 3], [1, 2, 3]]))

      assert_raise ArgumentError, ~r/:sequences must be a percentage/, fn ->
        Plan.new([seed: 3, jobs: 2, scenes: @scenes, sequences: 101] ++ @sequence)
      end
    end
  end
end
