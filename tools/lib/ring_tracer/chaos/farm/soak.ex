defmodule RingTracer.Chaos.Farm.Soak do
  @moduledoc false
  # The chaos soak's farm mode (`mix ring_tracer.chaos --farm`): a head and
  # workers on this machine (`RingTracer.Chaos.Farm.Cluster`), a queue of
  # jobs (`RingTracer.Chaos.Farm.Schedule`: stills and short sequences from
  # two users), and faults on the seed's schedule, each due when the farm has
  # stored so many frames (and one more since the previous fault): the head
  # killed (SIGKILL) and started again, workers killed, frozen and added. At the end every frame the head stored
  # is fetched and hashed, and `RingTracer.Chaos.Farm.Checker` gives the
  # verdict: every job done, no frame lost, none stored twice, every frame
  # byte-identical to the same frame rendered alone.
  #
  # The nodes are `:peer` nodes of the calling process: after a failure
  # part-way they stop when it exits.
  #
  # A worker is killed or frozen only while at least two are up (the queue
  # never waits on no worker at all): a fault without a victim is counted as
  # skipped, and one still due when the last job ended as late.

  require Logger

  alias RingTracer.Chaos
  alias RingTracer.Chaos.Farm.{Checker, Cluster, References, Schedule}
  alias RingTracer.Chaos.Farm.Checker.{Frame, JobEnd}
  alias RingTracer.Farm

  @tick_ms 100

  defmodule Report do
    @moduledoc false
    # What a farm soak did and its verdict.
    @enforce_keys [:options, :verdict, :faults, :seconds, :ends]
    defstruct [:options, :verdict, :faults, :seconds, :ends]

    @type t :: %__MODULE__{
            options: keyword(),
            verdict: RingTracer.Chaos.Farm.Checker.t(),
            faults: %{atom() => non_neg_integer()},
            seconds: float(),
            ends: [RingTracer.Chaos.Farm.Checker.JobEnd.t()]
          }
  end

  @defaults [
    seed: 1,
    jobs: 60,
    workers: 3,
    width: 48,
    height: 36,
    speed: 300,
    freeze: 3_000,
    timeout: 1_800_000,
    log_level: :error
  ]

  @doc """
  Runs the soak; `on_event` gets a line for each fault and job end.

  ## Options

    * `:seed`, `:jobs`, `:faults` — the schedule's (`Schedule.new/1`)
    * `:workers` — workers at the start (default 3)
    * `:width`, `:height` — every frame's size (default 48 x 36)
    * `:speed` — each worker emulates a machine this many times slower
      (default 300), so that faults land while frames are traced
    * `:freeze` — how long a frozen worker stays stopped, ms (default 3000)
    * `:timeout` — the longest the queue may take, ms (default 30 min)
    * `:log_level` — the peers' logger level (default `:error`)
  """
  @spec run(keyword(), (String.t() -> any())) ::
          {:ok, Report.t()} | {:error, RingTracer.Error.t()}
  def run(opts \\ [], on_event \\ fn _ -> :ok end) do
    opts = Keyword.merge(@defaults, opts)
    started = System.monotonic_time(:millisecond)
    schedule = Schedule.new(Keyword.take(opts, [:seed, :jobs, :faults]))

    with {:ok, refs} <- References.hashes(schedule, opts[:width], opts[:height]) do
      name = "rt_farm_soak_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}"
      dir = Path.join(System.tmp_dir!(), name)

      try do
        cluster = Cluster.start(dir, opts[:workers], Keyword.take(opts, [:speed, :log_level]))
        soak(cluster, schedule, refs, opts, started, on_event)
      after
        File.rm_rf(dir)
      end
    end
  end

  defp soak(cluster, schedule, refs, opts, started, on_event) do
    with {:ok, ids} <- submit(Cluster.head(cluster), schedule, opts) do
      deadline = started + opts[:timeout]
      tally = Map.new(Schedule.kinds() ++ [:skipped, :late, :dropped], &{&1, 0})
      run = %{cluster: cluster, ids: ids, faults: schedule.faults, tally: tally, last: -1}
      run = drive(run, opts, deadline, on_event)
      {cluster, _} = Cluster.thaw(run.cluster, :all)
      {ends, frames, twice} = collect(Cluster.head(cluster), schedule, ids, refs)
      seconds = (System.monotonic_time(:millisecond) - started) / 1000
      Cluster.stop(cluster)

      {:ok,
       %Report{
         options: opts,
         verdict: Checker.check(ends, frames, twice),
         faults: run.tally,
         seconds: seconds,
         ends: ends
       }}
    end
  end

  defp submit(head, schedule, opts) do
    Enum.reduce_while(schedule.jobs, {:ok, %{}}, fn job, {:ok, ids} ->
      frames =
        if job.frames == [1] and job.scene != "whitted_orbit.toml",
          do: [],
          else: [frames: job.frames]

      submission =
        [
          width: opts[:width],
          height: opts[:height],
          format: job.format,
          user: job.user,
          priority: job.priority,
          tags: job.tags
        ] ++ frames

      case Farm.submit(head, Chaos.scene_path(job.scene), submission) do
        {:ok, id} -> {:cont, {:ok, Map.put(ids, job.index, id)}}
        {:error, _} = error -> {:halt, error}
      end
    end)
  end

  # Polls the head until every job has ended, injecting each fault when the
  # frames stored reach its count.
  defp drive(run, opts, deadline, on_event) do
    {cluster, gone} = Cluster.thaw(run.cluster, :due)
    run = %{run | cluster: cluster, tally: Map.update!(run.tally, :dropped, &(&1 + length(gone)))}
    for node <- gone, do: on_event.("worker #{node} went down after its freeze")

    case Farm.jobs(Cluster.head(cluster), timeout: 5_000) do
      {:ok, infos} ->
        mine = Enum.filter(infos, &(&1.id in Map.values(run.ids)))
        stored = mine |> Enum.map(&length(&1.done)) |> Enum.sum()

        cond do
          Enum.all?(mine, &RingTracer.Farm.Job.ended_state?(&1.state)) ->
            late = length(run.faults)
            %{run | faults: [], tally: Map.update!(run.tally, :late, &(&1 + late))}

          System.monotonic_time(:millisecond) > deadline ->
            on_event.("the queue did not end in time")
            run

          true ->
            run
            |> fire(stored, opts, on_event)
            |> tap(fn _ -> Process.sleep(@tick_ms) end)
            |> drive(opts, deadline, on_event)
        end

      {:error, error} ->
        on_event.("head: #{error.message}")
        Process.sleep(@tick_ms)
        drive(run, opts, deadline, on_event)
    end
  end

  # One fault at a time, and only once a frame was stored since the last
  # one: each meets a farm that made progress after the previous fault.
  defp fire(%{faults: [%{at: at} = fault | rest], last: last} = run, stored, opts, on_event)
       when at <= stored and stored > last do
    {cluster, outcome} = inject(run.cluster, fault, opts)
    on_event.("fault #{fault.kind} at #{stored} frames stored: #{outcome}")
    key = if outcome == :skipped, do: :skipped, else: fault.kind
    tally = Map.update!(run.tally, key, &(&1 + 1))
    %{run | cluster: cluster, faults: rest, tally: tally, last: stored}
  end

  defp fire(run, _stored, _opts, _on_event), do: run

  defp inject(cluster, %{kind: :head_kill}, _opts) do
    cluster = Cluster.kill_head(cluster)
    {cluster, "head #{Cluster.head(cluster)} killed and restarted"}
  end

  defp inject(cluster, %{kind: :worker_add}, _opts) do
    before = Map.keys(cluster.workers)
    cluster = Cluster.add_worker(cluster)
    {cluster, "added #{inspect(Map.keys(cluster.workers) -- before)}"}
  end

  defp inject(cluster, %{kind: kind, pick: pick}, opts) do
    case Cluster.up(cluster) do
      up when length(up) >= 2 ->
        node = Enum.at(up, rem(pick, length(up)))

        case kind do
          :worker_kill -> {Cluster.kill_worker(cluster, node), "killed #{node}"}
          :worker_freeze -> {Cluster.freeze_worker(cluster, node, opts[:freeze]), "froze #{node}"}
        end

      _ ->
        {cluster, :skipped}
    end
  end

  defp collect(head, schedule, ids, refs) do
    results =
      Enum.map(schedule.jobs, fn job ->
        id = ids[job.index]

        job_end =
          case Farm.status(head, id) do
            {:ok, info} -> %JobEnd{index: job.index, id: id, state: info.state, error: info.error}
            {:error, e} -> %JobEnd{index: job.index, id: id, state: :unknown, error: e.message}
          end

        frames =
          for n <- job.frames do
            got =
              case Farm.frame(head, id, n) do
                {:ok, bytes} -> References.sha(bytes)
                {:error, _} -> nil
              end

            expected = Map.fetch!(refs, {job.scene, n, job.format})
            %Frame{index: job.index, number: n, got: got, expected: expected}
          end

        {job_end, frames}
      end)

    twice =
      case Farm.overview(head) do
        {:ok, %{stored_twice: twice}} -> twice
        {:error, _} -> 0
      end

    {Enum.map(results, &elem(&1, 0)), Enum.flat_map(results, &elem(&1, 1)), twice}
  end

  @doc "The summary table."
  @spec format(Report.t()) :: String.t()
  def format(%Report{verdict: v, faults: f, options: o} = report) do
    rows = [
      {"jobs (done)", "#{v.jobs} (#{v.done})"},
      {"frames", v.frames},
      {"head restarts (kill -9)", f.head_kill},
      {"workers killed / frozen / added",
       "#{f.worker_kill} / #{f.worker_freeze} / #{f.worker_add}"},
      {"faults skipped: no victim / the queue had ended", "#{f.skipped} / #{f.late}"},
      {"workers down after a freeze", f.dropped},
      {"frames lost", v.lost},
      {"frames stored twice", v.twice},
      {"frames differing from the frame rendered alone", v.mismatches}
    ]

    head =
      "chaos --farm: seed #{o[:seed]}, #{o[:jobs]} jobs, #{o[:workers]} workers " <>
        "(speed #{o[:speed]}), #{o[:width]}x#{o[:height]}, freeze #{o[:freeze]} ms; " <>
        "#{:erlang.float_to_binary(report.seconds, decimals: 1)} s"

    wrong =
      for e <- report.ends, e.index in v.wrong do
        "job #{e.index} (id #{e.id}): #{e.state}#{if e.error, do: ": #{e.error}", else: ""}"
      end

    Enum.join(
      [head | Enum.map(rows, fn {k, val} -> "  " <> String.pad_trailing(k, 52) <> "#{val}" end)] ++
        wrong,
      "\n"
    )
  end

  @doc "Whether the soak passed (`Checker.passed?/1`)."
  @spec passed?(Report.t()) :: boolean()
  def passed?(%Report{verdict: v}), do: Checker.passed?(v)
end
