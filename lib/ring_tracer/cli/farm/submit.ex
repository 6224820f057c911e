defmodule RingTracer.CLI.Farm.Submit do
  @moduledoc false
  # `ringtracer submit SCENE --out FILE --farm HEAD [options]`: queues a still
  # or a sequence on a farm (`RingTracer.Farm.submit/3`) and prints the job's
  # id. The scene, and every file it references, is read here, confined as
  # `ringtracer render` reads it, and travels with the submission. Then it
  # waits and writes each frame to `--out` on this machine as it completes
  # (`RingTracer.CLI.Farm.Fetch`); `--no-wait` returns once the job is queued
  # (`ringtracer fetch ID` gets the frames later).
  #
  # Exit status as `ringtracer render`'s: 0 queued (and, when waiting, every
  # frame written), 1 failed (a bad scene, a head that cannot be reached, a
  # job that failed or was cancelled), 2 a usage error, 130/143 interrupted
  # (the job goes on on the farm).

  alias RingTracer.CLI.{Args, Console, Frames, Paths, Render}
  alias RingTracer.CLI.Farm.{Client, Fetch}
  alias RingTracer.Cluster.Distribution

  # The render options a farm job takes (the farm sets the rest).
  @render_switches [
    out: :string,
    width: :integer,
    height: :integer,
    depth: :integer,
    cutoff: :float,
    samples: :integer,
    frame: :integer,
    frames: :string,
    spd: :boolean,
    atoms: :integer,
    strategy: :string,
    layout: :string,
    split: :boolean,
    speeds: :string,
    allow_dir: :keep,
    quiet: :boolean
  ]
  @farm_switches [
    user: :string,
    priority: :integer,
    tags: :string,
    max_workers: :integer,
    wait: :boolean
  ]
  @switches @render_switches ++ @farm_switches ++ Client.switches()
  @aliases [o: :out, q: :quiet, w: :width]

  # Render's options a farm job cannot take, and why.
  @not_here %{
    children: "the farm sets a job's children from its workers' slots",
    nodes: "the farm places a job's children on its workers",
    children_per_node: "the farm sets a job's children from its workers' slots",
    local: "the farm places a job's children on its workers",
    window: "the farm sets a sequence's window",
    region: "a farm job renders whole frames",
    aim: "a farm job's ring does not aim its offers",
    preview: "a farm job has no preview of its own",
    stats: "a farm job's statistics stay on the head",
    timeline: "a farm job's timeline stays on the head",
    ownership: "a farm job's ownership image stays on the head",
    continue: "give it to `ringtracer fetch`, which skips the frames already there",
    progress: "a farm job prints each frame as it is written (-q for none)"
  }

  @doc "The text of `ringtracer submit --help`."
  @spec help() :: String.t()
  def help do
    """
    Usage: ringtracer submit SCENE --out FILE --farm HEAD [options]

    Queues SCENE on the farm whose head is HEAD (as `ringtracer farm` prints it) and
    prints the job's id. The scene and the files it references are read here, as
    `ringtracer render` reads them, and travel with the job: no worker reads a file.
    Then waits, writing each frame to FILE on this machine as the farm completes it
    (atomically: a file is whole or absent). A run of # in FILE is the frame number.

    Image (as `ringtracer render`):
      -o, --out FILE          where the frames go (required): .png or .exr
      -w, --width W, --height H, --depth D, --samples S, --cutoff C, --spd
          --frame F, --frames A-B   one frame, or frames A to B (default: a still, or
                              every frame when FILE holds a #)
          --atoms K, --strategy S, --layout L, --split, --speeds 1,2
          --allow-dir DIR     a folder besides the scene's own it may read meshes from

    Farm:
          --farm HEAD         the head's node name (default: $RINGTRACER_FARM)
          --user U            who submits, for fair shares (default $USER@host)
          --priority P        an integer, higher runs first (default 0)
          --tags a,b          run only on workers with all these tags
          --max-workers N     use at most N workers
          --no-wait           return once queued; `ringtracer fetch ID` gets the frames
      -q, --quiet             print the job's id alone, and errors

    Credentials (as `ringtracer worker`; never a secret on the command line):
          --cookie-file PATH  the farm's cookie (default ~/.erlang.cookie)
          --tls DIR           the farm's TLS certificates (default: your own)
          --sname NAME, --name NAME@HOST, --listen ADDR, --ports MIN-MAX, --insecure-plain

    Examples:
      ringtracer submit priv/scenes/balls_s2.nff -o balls.png --farm farm@localhost
      ringtracer submit orbit.toml -o frames/o_####.png --farm farm@localhost --no-wait
      ringtracer submit big.toml -o big.exr --priority 5 --tags big-mem --farm farm@host

    Exit status: 0 queued (and written, when waiting), 1 failed (scene, farm, job), 2
    usage error, 130/143 interrupted: the job goes on; `ringtracer fetch ID` gets it.
    """
  end

  @doc "Runs the command with `argv` and returns its exit status."
  @spec run([String.t()]) :: non_neg_integer()
  def run(argv) do
    case execute(argv) do
      :ok ->
        0

      {:error, status, message} ->
        IO.puts(Console.err(), "ringtracer submit: #{message}")
        status
    end
  end

  @doc "Runs the command: `:ok`, or the exit status and the message to show."
  @spec execute([String.t()]) :: :ok | {:error, pos_integer(), String.t()}
  def execute(argv) do
    case Args.parse(argv, @switches, %{}, @aliases) do
      :help ->
        IO.write(help())
        :ok

      {:error, message} ->
        {:error, 2, not_here(argv) || message}

      {:ok, opts, [scene]} ->
        scene |> submit(opts) |> outcome()

      {:ok, _opts, []} ->
        {:error, 2, "give a scene file: ringtracer submit SCENE --out FILE --farm HEAD"}

      {:ok, _opts, extra} ->
        {:error, 2, "one scene at a time, got: #{Enum.join(extra, " ")}"}
    end
  end

  # A render option that is not a farm job's gets its reason.
  defp not_here(argv) do
    Enum.find_value(argv, fn arg ->
      key =
        arg
        |> String.split("=", parts: 2)
        |> hd()
        |> String.trim_leading("-")
        |> String.replace("-", "_")

      with true <- String.starts_with?(arg, "--"),
           {atom, why} <- Enum.find(@not_here, fn {k, _} -> Atom.to_string(k) == key end) do
        "#{Args.flag(atom)} is not for a farm job: #{why}"
      else
        _ -> nil
      end
    end)
  end

  defp submit(scene_arg, opts) do
    opts = Paths.expand(opts, [:out, :allow_dir])
    scene_path = Paths.expand(scene_arg)

    with {:ok, head} <- Client.head(opts),
         :ok <- usage_of(Distribution.refuse_cookie(opts)),
         :ok <- Render.check_ranges(opts),
         {:ok, out} <- required_out(opts),
         :ok <- Frames.check_out(out),
         {:ok, render} <- Render.render_opts(Keyword.take(opts, render_keys())),
         {:ok, farm} <- farm_opts(opts),
         :ok <- usage_of(RingTracer.Output.check([{:image, out}], [scene_path])),
         allow_dirs = Keyword.get_values(opts, :allow_dir),
         {:ok, scene} <- failed_of(RingTracer.Scene.load(scene_path, allow_dirs: allow_dirs)),
         {:ok, plan} <- Frames.plan(opts, out, scene.frames, scene.source.name),
         paths = Enum.map(plan.numbers, &Frames.path(plan, &1)),
         :ok <- usage_of(RingTracer.Output.check_targets(:image, paths)),
         :ok <-
           usage_of(RingTracer.Output.check_inputs(Enum.map(paths, &{:image, &1}), scene.files)),
         {:ok, dir} <- failed_of(RingTracer.Output.open_dir(Path.dirname(hd(paths)))),
         :ok <- Client.connect(opts, head),
         :ok <- not_interrupted(),
         job_opts = render ++ farm ++ [frames: plan.numbers, out: out],
         {:ok, id} <- failed_of(RingTracer.Farm.submit(head, scene, job_opts)) do
      quiet? = opts[:quiet] == true
      say_queued(id, head, scene, plan, quiet?)

      # a still and a sequence alike, unless --no-wait
      if Keyword.get(opts, :wait, true) do
        fetch = %{wait: true, skip: [], quiet: quiet?}
        head |> Fetch.run(id, plan, dir, fetch) |> Fetch.verdict(id, head)
      else
        :ok
      end
    end
  end

  # An interrupt before the job is queued: nothing is.
  defp not_interrupted do
    case RingTracer.CLI.Signals.pending() do
      nil ->
        :ok

      signal ->
        what = if signal == :sigint, do: "interrupted", else: "terminated"
        {:interrupted, {signal, "#{what}; nothing queued"}}
    end
  end

  defp render_keys,
    do: Keyword.keys(@render_switches) -- [:out, :frame, :frames, :allow_dir, :quiet]

  defp farm_opts(opts) do
    tags =
      case opts[:tags] do
        nil -> []
        text -> text |> String.split(",", trim: true) |> Enum.map(&String.trim/1)
      end

    with :ok <- Args.in_range(opts, :max_workers, 1..1_000_000) |> usage_of() do
      {:ok,
       [tags: tags]
       |> put(:user, opts[:user])
       |> put(:priority, opts[:priority])
       |> put(:max_workers, opts[:max_workers])}
    end
  end

  defp put(list, _key, nil), do: list
  defp put(list, key, value), do: Keyword.put(list, key, value)

  defp required_out(opts) do
    case opts[:out] do
      nil -> {:usage, "--out FILE is required (a .png or .exr file; a # in it for a sequence)"}
      out -> {:ok, out}
    end
  end

  defp say_queued(id, _head, _scene, _plan, true), do: IO.puts("#{id}")

  defp say_queued(id, head, scene, plan, false) do
    what =
      case plan.numbers do
        [n] -> "frame #{n}"
        numbers -> "#{length(numbers)} frames"
      end

    IO.puts("job #{id} queued on #{head}: #{scene.source.name}, #{what}")
  end

  defp outcome(:ok), do: :ok
  defp outcome({:usage, message}), do: {:error, 2, Render.cli_names(message)}
  defp outcome({:failed, message}), do: {:error, 1, message}
  defp outcome({:error, message}) when is_binary(message), do: {:error, 1, message}

  defp outcome({:interrupted, {signal, message}}),
    do: {:error, RingTracer.CLI.Signals.exit_status(signal), message}

  defp usage_of({:error, %RingTracer.Error{message: message}}), do: {:usage, message}
  defp usage_of({:error, message}) when is_binary(message), do: {:usage, message}
  defp usage_of(ok), do: ok

  # A farm refusing an option before anything is queued is a usage error.
  defp failed_of({:error, %RingTracer.Error{reason: :invalid_option, message: message}}),
    do: {:usage, message}

  defp failed_of({:error, %RingTracer.Error{message: message}}), do: {:failed, message}
  defp failed_of(ok), do: ok
end
