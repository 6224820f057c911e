defmodule RingTracer.Farm.Dashboard.ViewTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Farm.Dashboard.View

  alias RingTracer.Farm.{JobInfo, WorkerInfo}
  alias RingTracer.Farm.Dashboard.View

  defp job(id, state, opts \\ []),
    do: struct!(%JobInfo{id: id, user: "u", state: state}, opts)

  test "jobs not ended first, the last 20 ended, the queue by priority then submission" do
    ended = for id <- 1..25, do: job(id, :done)
    live = [job(26, :running), job(27, :queued), job(28, :queued, priority: 5)]
    view = View.new(%{workers: [], jobs: ended ++ live}, :head@h, 1)

    assert Enum.map(view.jobs, & &1.id) == [26, 27, 28] ++ Enum.to_list(6..25)
    assert view.ended_omitted == 5
    assert view.queue == [28, 27]
  end

  test "a worker is working while it has a job" do
    workers = [
      %WorkerInfo{node: :a@h, job: 3, speed: 2, slots: 4},
      %WorkerInfo{node: :b@h, tags: ["gpu"]}
    ]

    view = View.new(%{workers: workers, jobs: []}, :head@h, 1)

    assert [%{node: "a@h", state: "working", job: 3, speed: 2, slots: 4}, %{state: "idle"} = b] =
             view.workers

    assert b.tags == ["gpu"]
  end

  test "markup is escaped and bytes that are not UTF-8 replaced in the JSON" do
    jobs = [
      job(1, :failed,
        user: "<script>alert('&')</script>",
        scene: <<"a", 0xC3>>,
        error: "x > y",
        frames: [1, 2],
        done: [1]
      )
    ]

    json = View.encode(View.new(%{workers: [], jobs: jobs}, :head@h, 1))
    refute json =~ ~r/[<>&]/
    [decoded] = :jiffy.decode(json, [:return_maps, :use_nil])["jobs"]
    assert decoded["user"] == "<script>alert('&')</script>"
    assert decoded["scene"] == "a\uFFFD"
    assert decoded["error"] == "x > y"
    assert {decoded["frames"], decoded["done"], decoded["state"]} == {2, 1, "failed"}
  end
end
