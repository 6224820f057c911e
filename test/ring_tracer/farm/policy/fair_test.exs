defmodule RingTracer.Farm.Policy.FairTest do
  use ExUnit.Case, async: true

  alias RingTracer.Farm.Policy.{Fair, View}

  doctest Fair

  defp job(id, user, opts \\ []) do
    %{
      id: id,
      user: user,
      priority: opts[:priority] || 0,
      tags: opts[:tags] || [],
      max_workers: opts[:max_workers],
      state: if(opts[:workers], do: :running, else: :queued),
      workers: opts[:workers] || []
    }
  end

  defp workers(spec), do: for({n, tags, job} <- spec, do: %{node: n, tags: tags, job: job})
  defp idle(nodes), do: workers(for n <- nodes, do: {n, [], nil})

  test "one queued job takes every worker" do
    assert Fair.assign(%View{jobs: [job(1, "ann")], workers: idle([:b, :a])}) ==
             [{:start, 1, [:a, :b]}]
  end

  test "a user's jobs are served in order; another user gets an equal share" do
    jobs = [job(1, "ann"), job(2, "ann"), job(3, "bob")]

    assert Fair.assign(%View{jobs: jobs, workers: idle([:a, :b, :c, :d])}) ==
             [{:start, 1, [:a, :c]}, {:start, 3, [:b, :d]}]
  end

  test "a higher priority takes workers from a lower one" do
    jobs = [job(1, "ann", workers: [:a, :b]), job(2, "bob", priority: 5)]
    view = %View{jobs: jobs, workers: workers([{:a, [], 1}, {:b, [], 1}])}
    assert Fair.assign(view) == [{:release, 1, :a}, {:release, 1, :b}, {:start, 2, [:a, :b]}]
  end

  test "tags and caps limit what a job takes; the rest goes to others" do
    jobs = [job(1, "ann", tags: ["big-mem"], priority: 1), job(2, "ann", max_workers: 1)]

    view = %View{
      jobs: jobs,
      workers: workers([{:a, ["big-mem"], nil}, {:b, [], nil}, {:c, [], nil}])
    }

    assert Fair.assign(view) == [{:start, 1, [:a]}, {:start, 2, [:b]}]
  end

  test "a running job gains a worker that joins, and nothing moves when the shares hold" do
    jobs = [job(1, "ann", workers: [:a]), job(2, "bob", workers: [:b])]
    view = %View{jobs: jobs, workers: workers([{:a, [], 1}, {:b, [], 2}, {:c, [], nil}])}
    assert Fair.assign(view) == [{:grow, 1, :c}]

    view = %View{jobs: jobs, workers: workers([{:a, [], 1}, {:b, [], 2}])}
    assert Fair.assign(view) == []
  end

  test "every worker is given to at most one job, and only to jobs it fits" do
    for seed <- 1..200 do
      :rand.seed(:exsss, {seed, 2, 3})
      nodes = for i <- 1..:rand.uniform(6), do: :"w#{i}"
      tagged = for n <- nodes, do: {n, Enum.take_random(["x", "y"], :rand.uniform(3) - 1)}

      jobs =
        for id <- 1..:rand.uniform(5) do
          job(id, Enum.random(["ann", "bob", "cy"]),
            priority: :rand.uniform(2),
            tags: Enum.take_random(["x", "y"], :rand.uniform(2) - 1),
            max_workers: Enum.random([nil, 1, 2])
          )
        end

      view = %View{jobs: jobs, workers: workers(for {n, t} <- tagged, do: {n, t, nil})}
      effects = Fair.assign(view)
      given = for {:start, id, ns} <- effects, n <- ns, do: {id, n}
      assert length(given) == length(Enum.uniq_by(given, &elem(&1, 1)))

      for {id, n} <- given do
        job = Enum.find(jobs, &(&1.id == id))
        assert Enum.all?(job.tags, &(&1 in Keyword.fetch!(tagged, n)))
      end

      for {:start, id, ns} <- effects do
        job = Enum.find(jobs, &(&1.id == id))
        assert job.max_workers == nil or length(ns) <= job.max_workers
      end
    end
  end
end
