defmodule Mix.Tasks.RingTracer.Chaos do
  @shortdoc "Chaos soak: concurrent jobs across peer nodes while processes and nodes die"
  @help """
  Runs concurrent jobs of several scenes across peer nodes on this machine
  and, by a plan fixed by the seed, kills grandchildren, children and whole
  nodes and freezes nodes at random moments; then prints jobs run, faults
  injected by kind, atoms lost or traced twice, images differing from a
  clean render, sequences run and their frames lost, delivered twice or
  differing from that frame's clean render, and the median and worst
  messages per atom. It fails (a non-zero exit) if any atom was lost or
  traced twice, any image or frame differs, any frame was lost or
  delivered twice, or a parent or child of a job is still alive on this
  node after the last job.

      mix ring_tracer.chaos [--seed 1] [--jobs 100] [--concurrency 3] [--nodes 3]
                            [--scenes balls_s2.nff,tetra_s3.nff,...] [--faults-per-job 2]
                            [--weights grandchild=3,child=3,node=1,freeze=1]
                            [--strategies ring,master,steal,static]
                            [--children 3-6] [--atoms 4-8] [--slowdown 300-1000]
                            [--sequences 20] [--sequence-scene whitted_orbit.toml]
                            [--frames 2-4] [--window 1-3]
                            [--width 96] [--height 72] [--liveness 1500] [--freeze MS]
                            [--timeout 60000] [--only 4,17] [--verbose]

  `--scenes` takes names under `priv/scenes` or paths; `--children`,
  `--atoms` (per child) and `--slowdown` (each child's speed factor, see
  `RingTracer.render/2`'s `:speeds`) are ranges the plan draws from, for
  each job; `--sequences` is the percentage of jobs that render a sequence
  (`RingTracer.render_sequence/2`, 0 for none) of `--sequence-scene`'s
  frames, `--frames` how many of them (drawn among all its frames) and
  `--window` the frames in flight, both ranges; `--weights` how often
  each fault kind is drawn (0 leaves it out); `--liveness` is the jobs'
  liveness timeout and `--freeze` how long a frozen node stays stopped
  (default twice the liveness); `--only` reruns some jobs of the seed's plan
  (as the list of jobs that went wrong names them). `--verbose` prints a
  line per job as it ends and lets this node and the peers log warnings
  (the soak makes nodes drop on purpose, so they log a lot); otherwise they
  log errors only. What each figure means is in `RingTracer.Chaos`.
  `--help` (or `-h`) prints this text and starts nothing.

  ## Farm mode

      mix ring_tracer.chaos --farm [--seed 1] [--jobs 60] [--workers 3]
                                   [--width 48] [--height 36] [--speed 300]
                                   [--freeze 3000] [--duration MS] [--verbose]

  A farm head and `--workers` workers (peer nodes), a queue of `--jobs`
  stills and short sequences from two users, and faults on the seed's
  schedule: the head killed (SIGKILL) and restarted, workers killed, frozen
  and added (`RingTracer.Chaos.Farm.Soak`). `--speed` makes each worker
  emulate a machine that many times slower, `--duration` is the longest the
  queue may take (ms, default 30 min). It prints jobs, frames, faults and
  frames lost, stored twice and differing from the frame rendered alone,
  and fails (a non-zero exit) unless every job is done and those are 0.
  """
  @moduledoc @help
  use Mix.Task

  alias RingTracer.Chaos
  alias RingTracer.Chaos.Farm.Soak
  alias RingTracer.Chaos.Plan

  @switches [
    seed: :integer,
    jobs: :integer,
    concurrency: :integer,
    nodes: :integer,
    scenes: :string,
    faults_per_job: :integer,
    weights: :string,
    strategies: :string,
    children: :string,
    atoms: :string,
    slowdown: :string,
    sequences: :integer,
    sequence_scene: :string,
    frames: :string,
    window: :string,
    width: :integer,
    height: :integer,
    liveness: :integer,
    freeze: :integer,
    timeout: :integer,
    only: :string,
    verbose: :boolean,
    farm: :boolean,
    workers: :integer,
    speed: :integer,
    duration: :integer
  ]

  @farm_only [:workers, :speed, :duration]
  @farm_keys [:seed, :jobs, :width, :height, :freeze, :verbose | @farm_only]

  @impl Mix.Task
  def run(argv) do
    if Enum.any?(argv, &(&1 in ["--help", "-h"])),
      do: Mix.shell().info(@help),
      else: soak(argv)
  end

  defp soak(argv) do
    opts = parse(argv)

    cond do
      opts[:farm] ->
        farm(Keyword.delete(opts, :farm))

      key = Enum.find(@farm_only, &Keyword.has_key?(opts, &1)) ->
        Mix.raise("--#{key} needs --farm")

      true ->
        ring(opts)
    end
  end

  defp farm(opts) do
    case Enum.find(Keyword.keys(opts), &(&1 not in @farm_keys)) do
      nil -> :ok
      key -> Mix.raise("--#{dashed(key)} is not an option of --farm")
    end

    {verbose, opts} = Keyword.pop(opts, :verbose, false)
    {duration, opts} = Keyword.pop(opts, :duration)
    opts = if duration, do: Keyword.put(opts, :timeout, duration), else: opts
    Mix.Task.run("app.start")
    level = if verbose, do: :warning, else: :error
    previous = Logger.level()
    Logger.configure(level: level)
    on_event = fn line -> if verbose, do: Mix.shell().info(line) end

    report =
      try do
        RingTracer.Chaos.Farm.Soak.run(Keyword.put(opts, :log_level, level), on_event)
      after
        Logger.configure(level: previous)
      end

    case report do
      {:ok, report} ->
        Mix.shell().info(Soak.format(report))
        v = report.verdict

        unless Soak.passed?(report) do
          Mix.raise(
            "chaos soak --farm failed: #{v.jobs - v.done} jobs not done, #{v.lost} frames lost, " <>
              "#{v.twice} stored twice, #{v.mismatches} differing " <>
              "(seed #{report.options[:seed]})"
          )
        end

      {:error, error} ->
        Mix.raise("chaos soak --farm: #{error.message}")
    end
  end

  defp ring(opts) do
    {verbose, opts} = Keyword.pop(opts, :verbose, false)
    Mix.Task.run("app.start")
    level = if verbose, do: :warning, else: :error
    previous = Logger.level()
    Logger.configure(level: level)

    report =
      try do
        Chaos.run(Keyword.put(opts, :log_level, level), fn outcome ->
          if verbose,
            do: Mix.shell().info("job #{outcome.job.index}: #{Chaos.describe(outcome)}")
        end)
      rescue
        # A missing scene, or jobs that render/2 would refuse.
        e in ArgumentError -> Mix.raise(Exception.message(e))
      after
        Logger.configure(level: previous)
      end

    Mix.shell().info(Chaos.format(report))

    unless Chaos.passed?(report) do
      t = Chaos.totals(report)

      Mix.raise(
        "chaos soak failed: #{t.lost} atoms lost, #{t.twice} traced twice, " <>
          "#{t.images_differing} images differing, #{t.frames_lost} frames lost, " <>
          "#{t.frames_twice} frames delivered twice, #{t.frames_differing} frames differing, " <>
          "#{t.left_behind} processes left " <>
          "(seed #{report.options[:seed]})"
      )
    end
  end

  @doc false
  @spec parse([String.t()]) :: keyword()
  def parse(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, [], []} -> Enum.map(opts, &convert/1)
      {_, rest, []} -> Mix.raise("unexpected arguments: #{Enum.join(rest, " ")}")
      {_, _, invalid} -> Mix.raise("invalid options: #{inspect(invalid)}")
    end
  end

  defp convert({key, n})
       when key in [:jobs, :concurrency, :width, :height, :liveness, :freeze, :timeout] or
              key in [:workers, :speed, :duration] do
    if n > 0, do: {key, n}, else: Mix.raise("--#{key} must be positive, got #{n}")
  end

  defp convert({key, n}) when key in [:nodes, :faults_per_job] do
    if n >= 0, do: {key, n}, else: Mix.raise("--#{dashed(key)} must be 0 or more, got #{n}")
  end

  defp convert({:sequences, n}) do
    if n in 0..100,
      do: {:sequences, n},
      else: Mix.raise("--sequences is a percentage from 0 to 100, got #{n}")
  end

  defp convert({:scenes, list}), do: {:scenes, names(list)}

  defp convert({key, text}) when key in [:children, :atoms, :slowdown, :frames, :window] do
    range =
      case Enum.map(String.split(text, "-"), &Integer.parse/1) do
        [{n, ""}] -> n..n
        [{a, ""}, {b, ""}] when a <= b -> a..b
        _ -> nil
      end

    if range && range.first > 0,
      do: {key, range},
      else: Mix.raise("--#{key} takes N or MIN-MAX (positive integers), got #{text}")
  end

  defp convert({:strategies, list}) do
    known = RingTracer.Strategies.names()

    {:strategies,
     Enum.map(names(list), fn name ->
       Enum.find(known, &(Atom.to_string(&1) == name)) ||
         Mix.raise("unknown strategy #{name}; one of #{Enum.join(known, ", ")}")
     end)}
  end

  defp convert({:weights, text}) do
    given =
      Map.new(names(text), fn pair ->
        with [name, w] <- String.split(pair, "="),
             kind when kind != nil <- Enum.find(Plan.kinds(), &(Atom.to_string(&1) == name)),
             {w, ""} when w >= 0 <- Integer.parse(w) do
          {kind, w}
        else
          _ ->
            Mix.raise(
              "--weights takes KIND=N,... with KIND one of #{Enum.join(Plan.kinds(), ", ")}; got #{pair}"
            )
        end
      end)

    weights = Enum.map(Plan.default_weights(), fn {k, w} -> {k, Map.get(given, k, w)} end)

    if Enum.all?(weights, &(elem(&1, 1) == 0)), do: Mix.raise("--weights leaves no fault kind")
    {:weights, weights}
  end

  defp convert({:only, list}) do
    {:only,
     Enum.map(names(list), fn i ->
       case Integer.parse(i) do
         {n, ""} when n >= 0 -> n
         _ -> Mix.raise("--only takes job indexes, got #{i}")
       end
     end)}
  end

  defp convert(other), do: other

  defp names(text), do: text |> String.split(",", trim: true) |> Enum.map(&String.trim/1)

  defp dashed(key), do: key |> Atom.to_string() |> String.replace("_", "-")
end
