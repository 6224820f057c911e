defmodule RingTracer.Farm.Policy.Fair do
  @moduledoc false
  # The farm's default policy (`RingTracer.Farm.Policy`): priorities first,
  # then fair shares between submitters.
  #
  #   * Jobs of a higher priority take the workers they can use before any
  #     job of a lower one; a lower job gets only workers that no higher job
  #     can take (for its tags or its cap).
  #   * Within a priority, the submitters (users) take workers in turns, one
  #     at a time, so two users with jobs get half the workers each, whatever
  #     how many jobs each has queued; a user's own jobs are served in the
  #     order they were submitted.
  #   * A job takes only workers that have every tag it asks for, and at most
  #     `max_workers` of them.
  #   * A worker stays with its job where the shares allow it: a job keeps its
  #     own workers before it is given others, so a new job or user takes
  #     workers from the others only down to the fair share.

  @behaviour RingTracer.Farm.Policy

  alias RingTracer.Farm.Policy.View

  @doc """
      iex> alias RingTracer.Farm.Policy.{Fair, View}
      iex> workers = for n <- [:w1, :w2, :w3, :w4], do: %{node: n, tags: [], job: 1}
      iex> running = %{id: 1, user: "ann", priority: 0, tags: [], max_workers: nil, state: :running, workers: [:w1, :w2, :w3, :w4]}
      iex> queued = %{id: 2, user: "bob", priority: 0, tags: [], max_workers: nil, state: :queued, workers: []}
      iex> Fair.assign(%View{jobs: [running, queued], workers: workers})
      [{:release, 1, :w2}, {:release, 1, :w4}, {:start, 2, [:w2, :w4]}]
  """
  @impl true
  def assign(%View{jobs: jobs, workers: workers}) do
    nodes = workers |> Enum.map(& &1.node) |> Enum.sort()
    tags = Map.new(workers, &{&1.node, MapSet.new(&1.tags)})
    current = Map.new(workers, &{&1.node, &1.job})

    target =
      jobs
      |> Enum.group_by(& &1.priority)
      |> Enum.sort_by(fn {priority, _} -> -priority end)
      |> Enum.reduce({%{}, nodes}, fn {_priority, level}, {target, free} ->
        share(level, target, free, tags, current)
      end)
      |> elem(0)

    effects(jobs, target)
  end

  # One priority level: users take turns, one worker a turn, until no user
  # can take one.
  defp share(level, target, free, tags, current) do
    users =
      level
      |> Enum.sort_by(& &1.id)
      |> Enum.group_by(& &1.user)
      |> Enum.sort_by(fn {user, _} -> user end)

    turns(users, target, free, tags, current)
  end

  defp turns(users, target, free, tags, current) do
    {target, free, took?} =
      Enum.reduce(users, {target, free, false}, fn {_user, jobs}, {target, free, took?} ->
        case pick(jobs, target, free, tags, current) do
          {job_id, node} ->
            {Map.update(target, job_id, [node], &[node | &1]), List.delete(free, node), true}

          nil ->
            {target, free, took?}
        end
      end)

    if took?, do: turns(users, target, free, tags, current), else: {target, free}
  end

  # The user's first job, in submission order, that can take a worker, and
  # the worker: its own before any other, then an idle one, then any.
  defp pick(jobs, target, free, tags, current) do
    Enum.find_value(jobs, fn job ->
      held = length(Map.get(target, job.id, []))
      fits = Enum.filter(free, &fits?(job, tags[&1]))

      cond do
        job.max_workers != nil and held >= job.max_workers -> nil
        fits == [] -> nil
        true -> {job.id, choose(fits, job.id, current)}
      end
    end)
  end

  defp fits?(job, worker_tags), do: Enum.all?(job.tags, &MapSet.member?(worker_tags, &1))

  defp choose(fits, job_id, current) do
    Enum.find(fits, &(current[&1] == job_id)) || Enum.find(fits, &(current[&1] == nil)) ||
      hd(fits)
  end

  # Releases first (a worker moves only once its old job let it go), then
  # grows and starts, each job's workers in node order.
  defp effects(jobs, target) do
    releases =
      for job <- jobs,
          job.state == :running,
          node <- Enum.sort(job.workers),
          node not in Map.get(target, job.id, []),
          do: {:release, job.id, node}

    gains =
      Enum.flat_map(jobs, fn job ->
        wanted = target |> Map.get(job.id, []) |> Enum.sort()

        case job.state do
          :queued when wanted != [] -> [{:start, job.id, wanted}]
          :queued -> []
          :running -> for node <- wanted, node not in job.workers, do: {:grow, job.id, node}
        end
      end)

    releases ++ gains
  end
end
