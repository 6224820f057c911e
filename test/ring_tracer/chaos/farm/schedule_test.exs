defmodule RingTracer.Chaos.Farm.ScheduleTest do
  use ExUnit.Case, async: true

  alias RingTracer.Chaos.Farm.Schedule
  alias RingTracer.Chaos.Farm.Schedule.{Fault, JobSpec}

  doctest Schedule

  test "a schedule is a function of its seed" do
    assert Schedule.new(seed: 42, jobs: 60) == Schedule.new(seed: 42, jobs: 60)
    refute Schedule.new(seed: 42, jobs: 60) == Schedule.new(seed: 43, jobs: 60)
  end

  test "jobs: stills and short sequences from two users, drawn priorities, tags, formats" do
    %Schedule{jobs: jobs} = Schedule.new(seed: 5, jobs: 200)
    assert Enum.map(jobs, & &1.index) == Enum.to_list(0..199)

    for %JobSpec{} = job <- jobs do
      assert job.user in ["ann", "bob"]
      assert job.priority in 0..3
      assert job.tags in [[], [Schedule.tag()]]
      assert job.format in [:png, :exr]
      assert job.frames == Enum.sort(Enum.uniq(job.frames))
      assert Enum.all?(job.frames, &(&1 in 1..48))
      assert length(job.frames) in 1..4
      if job.scene != "whitted_orbit.toml", do: assert(job.frames == [1])
    end

    # every kind of draw comes up
    for {key, values} <- [user: ["ann", "bob"], format: [:png, :exr], tags: [[], ["soak"]]],
        value <- values,
        do: assert(Enum.any?(jobs, &(Map.fetch!(&1, key) == value)), "#{key} #{inspect(value)}")

    assert Enum.any?(jobs, &(length(&1.frames) > 1))
    assert Enum.any?(jobs, &(&1.scene == "balls_s2.nff"))
  end

  test "faults: as many of each kind as asked, due over the first 70% of the frames, in order" do
    s = Schedule.new(seed: 9, jobs: 60)
    frames = Schedule.frames(s)
    counts = Enum.frequencies_by(s.faults, & &1.kind)
    assert counts == %{head_kill: 3, worker_kill: 6, worker_freeze: 6, worker_add: 6}
    assert Enum.map(s.faults, & &1.at) == Enum.sort(Enum.map(s.faults, & &1.at))

    for %Fault{at: at, pick: pick} <- s.faults do
      assert at in 1..div(frames * 7, 10)
      assert pick >= 0
    end

    one_each = [head_kill: 1, worker_kill: 1, worker_freeze: 1, worker_add: 1]
    s = Schedule.new(seed: 1, jobs: 8, faults: one_each)
    assert Enum.sort(Enum.map(s.faults, & &1.kind)) == Enum.sort(Schedule.kinds())
    # the jobs do not depend on the faults asked for
    assert s.jobs == Schedule.new(seed: 1, jobs: 8).jobs
  end
end
