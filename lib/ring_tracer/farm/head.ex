defmodule RingTracer.Farm.Head do
  @moduledoc false
  # A farm's head: the workers that joined it, the jobs' runners, and the
  # subscribers waiting for frames. The queue itself is in Mnesia
  # (`RingTracer.Farm.Store`); this process asks the policy
  # (`RingTracer.Farm.Policy`) what should change whenever a job or a
  # worker comes or goes, and carries its effects out.

  use GenServer
  require Logger

  alias RingTracer.{Error, Names, Native}
  alias RingTracer.Farm.{Job, JobInfo, Policy, Runner, Store, WorkerInfo}

  defmodule State do
    @moduledoc false
    @enforce_keys [:policy, :dir, :frames_dir]
    defstruct [
      :policy,
      :dir,
      :frames_dir,
      workers: %{},
      running: %{},
      subscribers: %{}
    ]

    @type worker :: %{
            tags: [String.t()],
            slots: pos_integer(),
            speed: number(),
            joined_at: integer(),
            member: pid(),
            ref: reference(),
            job: pos_integer() | nil
          }
    # `since` (monotonic ms) and `frames` (how many it renders) describe the
    # ring the runner started; `atoms` its progress, `preview` its page.
    @type run :: %{
            runner: pid(),
            ref: reference(),
            workers: [node()],
            since: integer(),
            frames: non_neg_integer(),
            atoms: {non_neg_integer(), non_neg_integer()} | nil,
            preview: String.t() | nil
          }
    @type t :: %__MODULE__{
            policy: module(),
            dir: Path.t(),
            frames_dir: term(),
            workers: %{node() => worker()},
            running: %{pos_integer() => run()},
            subscribers: %{pos_integer() => [{pid(), reference()}]}
          }
  end

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: Names.farm_head())

  @impl true
  def init(opts) do
    dir = Path.expand(opts[:dir])

    with {:ok, _held} <- private_dir(dir),
         {:ok, frames_dir} <- private_dir(Path.join(dir, "frames")),
         :ok <- Store.open(Path.join(dir, "mnesia")) do
      # Jobs that were running when the head stopped run again, from the
      # frames they had not finished.
      for %Job{state: :running} = job <- Store.all(), do: Store.put(%{job | state: :queued})
      state = %State{policy: opts[:policy], dir: dir, frames_dir: frames_dir}
      {:ok, state}
    else
      {:error, %Error{} = error} -> {:stop, error}
    end
  end

  defp private_dir(path) do
    case Native.fs_private_dir(path, true) do
      {:ok, held} -> {:ok, held}
      {:error, {_, message}} -> {:error, Error.new(:farm, "#{path}: #{message}")}
    end
  end

  @impl true
  def handle_call({:join, node, %{tags: tags, slots: slots} = about, member}, _from, state) do
    # A worker of another build is refused before it is a worker (its
    # message names both builds); one too old to tell its build as well.
    case RingTracer.Cluster.Build.compare(node, Map.get(about, :build)) do
      :ok ->
        join(state, node, tags, slots, about, member)

      {:error, error} ->
        Logger.warning("farm: refused worker #{node}: #{error.message}")
        {:reply, {:error, error}, state}
    end
  end

  def handle_call({:submit, %Job{} = job}, _from, state) do
    job = Store.insert(%{job | state: :queued, submitted_at: System.os_time(:millisecond)})
    Logger.info("farm: job #{job.id} from #{job.user} queued (#{length(job.frames)} frames)")
    {:reply, {:ok, job.id}, reassign(state)}
  end

  def handle_call(:jobs, _from, state),
    do: {:reply, {:ok, Enum.map(Store.all(), &info(&1, state))}, state}

  def handle_call({:status, id}, _from, state) do
    case Store.get(id) do
      {:ok, job} -> {:reply, {:ok, info(job, state)}, state}
      :error -> {:reply, {:error, no_job(id)}, state}
    end
  end

  def handle_call(:workers, _from, state), do: {:reply, {:ok, workers(state)}, state}

  def handle_call(:overview, _from, state) do
    jobs = Enum.map(Store.all(), &info(&1, state))
    {:reply, {:ok, %{workers: workers(state), jobs: jobs, stored_twice: Store.twice()}}, state}
  end

  def handle_call({:cancel, id}, _from, state) do
    case Store.get(id) do
      :error ->
        {:reply, {:error, no_job(id)}, state}

      {:ok, job} ->
        if Job.ended?(job) do
          {:reply, {:error, Error.new(:farm, "job #{id} has ended (#{job.state})")}, state}
        else
          state = stop_runner(state, id)
          state = ended(state, job, :cancelled, nil)
          {:reply, :ok, reassign(state)}
        end
    end
  end

  def handle_call({:subscribe, id, pid}, _from, state) do
    case Store.get(id) do
      :error ->
        {:reply, {:error, no_job(id)}, state}

      {:ok, job} ->
        if Job.ended?(job) do
          send(pid, {RingTracer.Farm, id, {:end, job.state, job.error}})
          {:reply, :ok, state}
        else
          ref = Process.monitor(pid)
          subscribers = Map.update(state.subscribers, id, [{pid, ref}], &[{pid, ref} | &1])
          {:reply, :ok, %{state | subscribers: subscribers}}
        end
    end
  end

  def handle_call({:frame, id, n}, _from, state) do
    with {:ok, job} <- Store.get(id),
         true <- Store.done?(id, n) do
      path = Path.join(Native.fs_dir_path(state.frames_dir), Job.frame_file(job, n))

      case File.read(path) do
        {:ok, bytes} -> {:reply, {:ok, bytes}, state}
        {:error, reason} -> {:reply, {:error, Error.file(:farm, path, reason)}, state}
      end
    else
      :error -> {:reply, {:error, no_job(id)}, state}
      false -> {:reply, {:error, Error.new(:farm, "job #{id} has no frame #{n} done")}, state}
    end
  end

  @impl true
  def handle_info({:runner_frame, id, n}, state) do
    for {pid, _} <- Map.get(state.subscribers, id, []),
        do: send(pid, {RingTracer.Farm, id, {:frame, n}})

    {:noreply, state}
  end

  # What the dashboard shows of a running job, kept here only (not in Mnesia).
  def handle_info({:runner_preview, id, url}, state) when is_map_key(state.running, id),
    do: {:noreply, put_in(state.running[id].preview, url)}

  def handle_info({:runner_progress, id, done, total}, state)
      when is_map_key(state.running, id),
      do: {:noreply, put_in(state.running[id].atoms, {done, total})}

  # Only the job's current runner ends it (below: any other's end is
  # dropped): one stopped for a new one may have sent its end before it
  # stopped.
  def handle_info({:runner_end, id, runner, outcome}, %State{running: running} = state)
      when is_map_key(running, id) and
             :erlang.map_get(:runner, :erlang.map_get(id, running)) == runner do
    state = drop_run(state, id)

    state =
      case {Store.get(id), outcome} do
        {:error, _} -> state
        {{:ok, %Job{state: :cancelled}}, _} -> state
        {{:ok, job}, :done} -> ended(state, job, :done, nil)
        {{:ok, job}, {:failed, message}} -> ended(state, job, :failed, message)
        {{:ok, job}, {:retry, message}} -> retry(state, job, message)
        {{:ok, job}, {:lost, _message}} -> requeued(state, job)
      end

    {:noreply, reassign(state)}
  end

  def handle_info({:runner_end, _id, _stale, _outcome}, state), do: {:noreply, state}

  def handle_info({:DOWN, ref, :process, pid, reason}, state) do
    cond do
      node = worker_of(state, ref) ->
        Logger.info("farm: worker #{node} left (#{inspect(reason)})")
        {:noreply, reassign(forget_worker(state, node))}

      id = job_of(state, ref) ->
        state = drop_run(state, id)

        state =
          case Store.get(id) do
            {:ok, %Job{state: :running} = job} ->
              retry(state, job, "its runner exited: #{inspect(reason)}")

            _ ->
              state
          end

        {:noreply, reassign(state)}

      true ->
        subscribers =
          Map.new(state.subscribers, fn {id, subs} ->
            {id, Enum.reject(subs, fn {p, r} -> p == pid and r == ref end)}
          end)

        {:noreply, %{state | subscribers: subscribers}}
    end
  end

  def handle_info(_other, state), do: {:noreply, state}

  # A worker gone (or joining again): its job lets it go.
  defp forget_worker(state, node) do
    case Map.pop(state.workers, node) do
      {nil, _} ->
        state

      {worker, workers} ->
        Process.demonitor(worker.ref, [:flush])
        state = %{state | workers: workers}

        case worker.job && state.running[worker.job] do
          nil ->
            state

          run ->
            case List.delete(run.workers, node) do
              [] ->
                # Its last worker gone: the job waits for others, and this
                # is no failure of its own.
                requeue(state, worker.job)

              workers ->
                send(run.runner, {:release, node})
                put_in(state.running[worker.job].workers, workers)
            end
        end
    end
  end

  defp worker_of(state, ref),
    do: Enum.find_value(state.workers, fn {node, w} -> if w.ref == ref, do: node end)

  defp job_of(state, ref),
    do: Enum.find_value(state.running, fn {id, run} -> if run.ref == ref, do: id end)

  defp drop_run(state, id) do
    case Map.pop(state.running, id) do
      {nil, _} ->
        state

      {run, running} ->
        Process.demonitor(run.ref, [:flush])

        workers =
          Map.new(state.workers, fn {node, w} ->
            {node, if(w.job == id, do: %{w | job: nil}, else: w)}
          end)

        %{state | running: running, workers: workers}
    end
  end

  defp stop_runner(state, id) do
    case state.running[id] do
      nil ->
        state

      # Synchronous (the runner cancels its ring as it terminates), so that
      # no other runner of the job starts while this one still stores frames.
      run ->
        _ = DynamicSupervisor.terminate_child(Names.farm_runners(), run.runner)
        drop_run(state, id)
    end
  end

  @max_tries 3

  defp requeued(state, job) do
    :ok = Store.put(%{job | state: :queued})
    state
  end

  defp requeue(state, id) do
    state = stop_runner(state, id)
    {:ok, job} = Store.get(id)
    Store.put(%{job | state: :queued})
    state
  end

  defp retry(state, job, message) do
    if job.tries + 1 >= @max_tries do
      ended(state, job, :failed, message)
    else
      Logger.warning("farm: job #{job.id} will run again: #{message}")
      Store.put(%{job | state: :queued, tries: job.tries + 1})
      state
    end
  end

  defp ended(state, job, how, error) do
    Store.put(%{job | state: how, error: error, finished_at: System.os_time(:millisecond)})
    Logger.info("farm: job #{job.id} #{how}#{if error, do: ": #{error}", else: ""}")
    {subs, subscribers} = Map.pop(state.subscribers, job.id, [])

    for {pid, ref} <- subs do
      Process.demonitor(ref, [:flush])
      send(pid, {RingTracer.Farm, job.id, {:end, how, error}})
    end

    %{state | subscribers: subscribers}
  end

  # Asks the policy, then carries out its effects: releases first.
  defp reassign(%State{} = state) do
    jobs = Enum.reject(Store.all(), &Job.ended?/1)

    view = %Policy.View{
      jobs:
        Enum.map(jobs, fn job ->
          run = state.running[job.id]

          %{
            id: job.id,
            user: job.user,
            priority: job.priority,
            tags: job.tags,
            max_workers: job.max_workers,
            state: if(run, do: :running, else: :queued),
            workers: if(run, do: run.workers, else: [])
          }
        end),
      workers:
        for({node, w} <- state.workers, do: %{node: node, tags: w.tags, job: w.job})
        |> Enum.sort_by(& &1.node)
    }

    state.policy.assign(view) |> Enum.reduce(state, &apply_effect/2)
  end

  defp apply_effect({:release, id, node}, state) do
    case state.running[id] do
      nil ->
        state

      run ->
        state = put_in(state.workers[node].job, nil)
        workers = List.delete(run.workers, node)

        if workers == [] do
          # A ring with no workers left stops; the job waits for others.
          requeue(state, id)
        else
          send(run.runner, {:release, node})
          put_in(state.running[id].workers, workers)
        end
    end
  end

  defp apply_effect({:grow, id, node}, state) do
    case {state.running[id], state.workers[node]} do
      {%{} = run, %{} = worker} ->
        send(run.runner, {:grow, node, worker.slots})
        state = put_in(state.workers[node].job, id)
        put_in(state.running[id].workers, run.workers ++ [node])

      _ ->
        state
    end
  end

  defp apply_effect({:start, id, nodes}, state) do
    with {:ok, job} <- Store.get(id),
         false <- Job.ended?(job),
         true <- Enum.all?(nodes, &Map.has_key?(state.workers, &1)) do
      job = %{job | state: :running, started_at: job.started_at || System.os_time(:millisecond)}
      Store.put(job)
      workers = Enum.map(nodes, &{&1, state.workers[&1].slots})

      {:ok, runner} =
        DynamicSupervisor.start_child(
          Names.farm_runners(),
          {Runner, {job, workers, state.frames_dir, self()}}
        )

      run = %{
        runner: runner,
        ref: Process.monitor(runner),
        workers: nodes,
        since: System.monotonic_time(:millisecond),
        frames: length(job.frames -- Store.done(id)),
        atoms: nil,
        preview: nil
      }

      state = Enum.reduce(nodes, state, fn node, state -> put_in(state.workers[node].job, id) end)

      put_in(state.running[id], run)
    else
      _ -> state
    end
  end

  defp info(%Job{} = job, state) do
    done = Store.done(job.id)
    run = state.running[job.id]

    {progress, time_left} =
      JobInfo.estimate(
        length(job.frames),
        length(done),
        run && {run.frames, run.atoms},
        if(run, do: System.monotonic_time(:millisecond) - run.since, else: 0)
      )

    %JobInfo{
      id: job.id,
      user: job.user,
      state: job.state,
      scene: job.source.name,
      width: job.width,
      height: job.height,
      format: job.format,
      out: job.out,
      submitted_at: job.submitted_at,
      started_at: job.started_at,
      finished_at: job.finished_at,
      error: job.error,
      priority: job.priority,
      tags: job.tags,
      max_workers: job.max_workers,
      frames: job.frames,
      done: done,
      workers: get_in(state.running, [job.id, :workers]) || [],
      progress: progress,
      time_left: time_left,
      preview: run && run.preview
    }
  end

  defp workers(state) do
    state.workers
    |> Enum.map(fn {node, w} ->
      %WorkerInfo{
        node: node,
        tags: w.tags,
        slots: w.slots,
        speed: w.speed,
        job: w.job,
        joined_at: w.joined_at
      }
    end)
    |> Enum.sort_by(& &1.node)
  end

  defp no_job(id), do: Error.new(:farm, "no job #{id} on this farm")

  # A worker of this build joins (again): known by its node, watched through
  # its member process.
  defp join(state, node, tags, slots, about, member) do
    state = forget_worker(state, node)
    ref = Process.monitor(member)
    at = System.os_time(:millisecond)
    speed = Map.get(about, :speed, 1)

    worker = %{
      tags: tags,
      slots: slots,
      speed: speed,
      joined_at: at,
      member: member,
      ref: ref,
      job: nil
    }

    Logger.info("farm: worker #{node} joined (#{slots} slots, tags #{inspect(tags)})")
    {:reply, :ok, reassign(put_in(state.workers[node], worker))}
  end
end
