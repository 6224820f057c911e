defmodule RingTracer.CLI.Render do
  @moduledoc false
  # `ringtracer render`: renders a scene file through the ring and writes the
  # image. Shared by the launcher (booted straight from `erl`) and `mix
  # ring_tracer.render`; `help/0` is the text of `--help`.
  #
  # Of an animated scene it renders a sequence of frames, one file each
  # (`RingTracer.CLI.Frames`).
  #
  # Exit status: 0 the image (every frame of a sequence) was written, 1 the
  # render failed (a bad scene, a failed job, an output that could not be
  # written), 2 a usage error (an unknown option, a bad value), 130
  # interrupted (SIGINT), 143 terminated (SIGTERM).

  alias RingTracer.CLI.{Args, Console, Frames, Paths, Progress}
  alias RingTracer.Cluster.Distribution
  alias RingTracer.Job.Slowdown

  @render_switches [
    out: :string,
    children: :integer,
    atoms: :integer,
    width: :integer,
    height: :integer,
    depth: :integer,
    cutoff: :float,
    samples: :integer,
    frame: :integer,
    frames: :string,
    continue: :boolean,
    window: :integer,
    spd: :boolean,
    strategy: :string,
    layout: :string,
    aim: :boolean,
    split: :boolean,
    speeds: :string,
    stats: :string,
    timeline: :string,
    ownership: :string,
    nodes: :string,
    children_per_node: :integer,
    local: :boolean,
    allow_dir: :keep,
    quiet: :boolean,
    progress: :string,
    region: :string,
    preview: :integer
  ]
  @switches @render_switches ++ RingTracer.CLI.Worker.switches()
  @aliases [o: :out, q: :quiet, w: :width]

  @max RingTracer.Options.maxima()
  @limits RingTracer.Settings.limits()
  @ranges [
    children: 1..@max.children,
    atoms: 1..@max.atoms,
    width: 1..@limits.max_side,
    height: 1..@limits.max_side,
    depth: 1..@limits.max_depth,
    samples: 1..@limits.max_samples,
    frame: 1..@limits.max_frames,
    window: 1..RingTracer.Sequence.max_window(),
    children_per_node: 1..@max.children,
    preview: 0..65_535
  ]
  @accepted Map.merge(
              Map.new(@ranges, fn {k, a..b//1} -> {k, "an integer from #{a} to #{b}"} end),
              %{cutoff: "a number from 0 (no cut-off) to 1"}
            )

  @outputs [out: :image, stats: :stats, timeline: :timeline, ownership: :ownership]
  @distribution Keyword.keys(RingTracer.CLI.Worker.switches())

  @doc """
  Whether `argv` asks for a render that needs a VM of its own: one on other
  nodes starts distribution, which the resident server
  (`RingTracer.CLI.Server`) leaves to a command's own VM.

      iex> RingTracer.CLI.Render.own_vm?(["a.nff", "-o", "a.png", "--nodes", "w1@localhost"])
      true
      iex> RingTracer.CLI.Render.own_vm?(["a.nff", "--tls=certs", "-o", "a.png"])
      true
      iex> RingTracer.CLI.Render.own_vm?(["a.nff", "-o", "a.png", "--children", "4"])
      false
  """
  @spec own_vm?([String.t()]) :: boolean()
  def own_vm?(argv) do
    flags = Enum.map([:nodes | @distribution], &Args.flag/1)
    Enum.any?(argv, fn arg -> hd(String.split(arg, "=", parts: 2)) in flags end)
  end

  @doc "The switches `render` accepts."
  @spec switches() :: keyword()
  def switches, do: @switches

  @doc "The text of `ringtracer render --help`."
  @spec help() :: String.t()
  def help do
    """
    Usage: ringtracer render SCENE --out FILE [options]

    Renders SCENE (.nff, .toml or .obj) through a ring of children and writes FILE
    (.png, 8-bit sRGB, or .exr, linear float). Paths are relative to this folder; a
    leading ~ in one is your $HOME (also when `ringtracer serve` renders it).

    Of an animated scene, a run of # in FILE's name is the frame number, zero-padded
    (f_####.png: f_0007.png, f_12345.png): every frame is rendered, in one job, each
    written as soon as it is done. Without a #, frame 1 (or --frame F) alone.

    Image:
      -o, --out FILE          the image to write (required); # is the frame number
      -w, --width W           image width; alone, keeps the scene's aspect ratio
          --height H          image height; alone, keeps the scene's aspect ratio
          --depth D           ray-tree depth, eye ray = 1 (1-64, default #{RingTracer.Settings.shown_default(:depth)})
          --samples S         S x S samples per pixel (1-16, default #{RingTracer.Settings.shown_default(:samples)})
          --cutoff C          adaptive cut-off weight (default #{RingTracer.Settings.shown_default(:cutoff)}, 0 disables)
          --frame F           of an animated scene, frame F alone (from 1; default 1)
          --frames A-B        frames A to B (or N: frame N alone), one file each, named
                              by the # of --out (default with a #: all of them)
          --continue          skip the frames whose file is already there (whole: files
                              are written atomically); a sequence stopped goes on
          --window W          frames traced at once in a sequence (1-#{RingTracer.Sequence.max_window()}, default #{RingTracer.Sequence.default_window()})
          --spd               the SPD testing procedure (pixel corners, no cut-off)
          --region X0,Y0,X1,Y1  trace only that part: pixels (X1, Y1 excluded) or
                              fractions (0.25,0,0.75,0.5); exactly the whole render's pixels

    Ring:
          --children N        ring size (1-#{@max.children}, default: schedulers online)
          --atoms K           atoms per child (default #{RingTracer.Options.default(:atoms)}; N x K at most #{@max.atoms})
          --strategy S        ring (default), static, master or steal
          --layout L          strips (default) or interleaved
          --aim, --no-aim     ring: offers straight to the busiest sibling (default on strips)
          --split, --no-split ring: adaptive atoms, cut in pieces near the end (default off)
          --speeds 1,1,4      slowdown factor of each child, cyclic (1-#{Slowdown.max()})

    Reports:
          --stats FILE        the job's statistics, .json or .csv
          --timeline FILE     one lane per child, .svg
          --ownership FILE    the image tinted by the child that traced each atom, .png
      -q, --quiet             print nothing but errors
          --progress MODE     bar (a terminal's default), log (a line every 5 s), none
          --preview [PORT]    a live page of the render at the address printed (a free
                              port on 127.0.0.1 unless given; --listen ADDR widens it)

    Cluster (start workers with `ringtracer worker`):
          --nodes a@host,...  also place children on these nodes, round robin
          --children-per-node C   C children on each node instead
          --no-local          no children on this node
          --sname NAME, --name NAME@HOST    this node's name
          --cookie-file PATH  the cookie, in a file only you can read (default ~/.erlang.cookie)
          --listen ADDR, --ports MIN-MAX    where this node listens (default 127.0.0.1)
          --tls DIR           TLS certificates (default: your own, made on first use)
          --insecure-plain    plain TCP distribution: any local user who answers on port
                              4369 can read and alter it (--allow-foreign-epmd: even then)

    Files:
          --allow-dir DIR     a folder besides the scene's own it may read meshes from (repeatable)

    Examples:
      ringtracer render priv/scenes/balls_s2.nff --out balls.png
      ringtracer render scene.toml -o scene.exr --width 1920 --children 8
      ringtracer render balls.nff -o b.png --speeds 1,1,4 --timeline b.svg --stats b.json
      ringtracer render priv/scenes/whitted_orbit.toml -o frames/orbit_####.png --width 320

    Exit status: 0 written (or, with --continue, all there), 1 render failed, 2 usage
    error, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM). A sequence interrupted
    or failed keeps the frames written: each is whole.
    """
  end

  @doc """
  Runs the command with `argv`, printing its errors, and returns the exit
  status (see the moduledoc).
  """
  @spec run([String.t()]) :: non_neg_integer()
  def run(argv) do
    case execute(argv) do
      :ok ->
        0

      {:error, status, message} ->
        IO.puts(Console.err(), "ringtracer render: #{message}")
        status
    end
  end

  @doc """
  Runs the command with `argv`: `:ok`, or the exit status and the message
  to show. Writes what was written and the statistics to stdout, progress
  to stderr.
  """
  @spec execute([String.t()]) :: :ok | {:error, pos_integer(), String.t()}
  def execute(argv) do
    case Args.parse(preview_port(argv), @switches, @accepted, @aliases) do
      :help ->
        IO.write(help())
        :ok

      {:error, message} ->
        usage(message)

      {:ok, opts, [scene]} ->
        case prepare(scene, opts) do
          {:ok, job} -> go(job)
          {:usage, message} -> usage(message)
          {:error, message} -> failed(message)
        end

      {:ok, _opts, []} ->
        usage("give a scene file: ringtracer render SCENE --out FILE")

      {:ok, _opts, extra} ->
        usage("one scene at a time, got: #{Enum.join(extra, " ")}")
    end
  end

  # `--preview` takes an optional port: alone, it means a free one (0).
  defp preview_port(["--preview", next | rest]) do
    case Integer.parse(next) do
      {_, ""} -> ["--preview", next | preview_port(rest)]
      _ -> ["--preview=0" | preview_port([next | rest])]
    end
  end

  defp preview_port(["--preview"]), do: ["--preview=0"]
  defp preview_port([arg | rest]), do: [arg | preview_port(rest)]
  defp preview_port([]), do: []

  defp usage(message), do: {:error, 2, message}
  defp failed(message), do: {:error, 1, message}

  # Everything that can be known before the scene is read, in the order a
  # user fixes things: options, then outputs, then the cluster.
  defp prepare(scene_arg, opts) do
    with :ok <- check_ranges(opts),
         :ok <- usage_of(Distribution.refuse_cookie(opts)),
         opts =
           Paths.expand(opts, [
             :out,
             :stats,
             :timeline,
             :ownership,
             :cookie_file,
             :tls,
             :allow_dir
           ]),
         {:ok, out} <- required_out(opts),
         :ok <- Frames.check_out(out),
         {:ok, render_opts} <- render_opts(opts),
         render_opts = render_opts ++ pixels(opts),
         {:ok, mode} <- progress_mode(opts),
         outputs = for({key, kind} <- @outputs, path = opts[key], do: {kind, path}),
         scene = Paths.expand(scene_arg),
         :ok <- usage_of(RingTracer.Output.check(outputs, [scene])),
         :ok <- start(opts) do
      {:ok,
       %{
         scene: scene,
         scene_arg: scene_arg,
         out: out,
         opts: opts,
         render_opts: render_opts,
         outputs: outputs,
         mode: mode,
         allow_dirs: Keyword.get_values(opts, :allow_dir)
       }}
    end
  end

  @doc false
  # The integer options' ranges (also `ringtracer submit`'s).
  @spec check_ranges(keyword()) :: :ok | {:usage, String.t()}
  def check_ranges(opts) do
    Enum.reduce_while(@ranges, :ok, fn {key, range}, :ok ->
      case Args.in_range(opts, key, range) do
        :ok -> {:cont, :ok}
        {:error, message} -> {:halt, {:usage, message}}
      end
    end)
    |> case do
      :ok ->
        if (opts[:cutoff] || 0.0) < 0,
          do: {:usage, "--cutoff takes #{@accepted.cutoff}, got: #{opts[:cutoff]}"},
          else: :ok

      other ->
        other
    end
  end

  defp usage_of({:error, %RingTracer.Error{message: message}}), do: {:usage, message}
  defp usage_of(ok), do: ok

  defp required_out(opts) do
    case opts[:out] do
      nil -> {:usage, "--out FILE is required (a .png or .exr file)"}
      out -> {:ok, out}
    end
  end

  # The pixels' format: 8-bit when every image written is a PNG (the
  # image, or the frames' pattern, and the ownership map), whose tints the
  # children then send too.
  defp pixels(opts) do
    images = for key <- [:out, :ownership], path = opts[key], do: path

    case RingTracer.Pixels.for_files(images) do
      :srgb8 -> [pixels: :srgb8, ownership: opts[:ownership] != nil]
      :float -> [pixels: :float]
    end
  end

  defp progress_mode(opts) do
    tty? = Console.tty?()

    case {opts[:quiet], opts[:progress]} do
      {true, _} -> {:ok, :quiet}
      {_, nil} -> {:ok, if(tty?, do: :tty, else: :log)}
      {_, "bar"} -> {:ok, :tty}
      {_, "log"} -> {:ok, :log}
      {_, "none"} -> {:ok, :quiet}
      {_, other} -> {:usage, "--progress takes bar, log or none, got: #{other}"}
    end
  end

  defp start(opts) do
    with :ok <- distribution(opts) do
      case Application.ensure_all_started(:ring_tracer) do
        {:ok, _} -> :ok
        {:error, reason} -> {:error, "could not start :ring_tracer: #{inspect(reason)}"}
      end
    end
  end

  defp distribution(opts) do
    if opts[:nodes] do
      case Distribution.start(Keyword.take(opts, @distribution) ++ [generate: true]) do
        {:ok, _} -> :ok
        {:error, %RingTracer.Error{message: message}} -> {:error, message}
      end
    else
      :ok
    end
  end

  @doc false
  # The render's options from the command line's (also `ringtracer submit`'s).
  @spec render_opts(keyword()) :: {:ok, keyword()} | {:usage, String.t()}
  def render_opts(opts) do
    base =
      Keyword.drop(opts, [
        :out,
        :stats,
        :timeline,
        :ownership,
        :allow_dir,
        :quiet,
        :progress,
        :frames,
        :continue,
        :window,
        :preview | @distribution
      ])

    with {:ok, o} <- choice(base, :strategy, RingTracer.Strategies.names()),
         {:ok, o} <- ring_options(o),
         {:ok, o} <- choice(o, :layout, RingTracer.Layout.orders()),
         {:ok, o} <- speeds(o),
         {:ok, o} <- region(o) do
      {:ok, o |> nodes() |> preview(opts)}
    end
  end

  # `--aim`, `--no-aim`, `--split`: the ring's own options, given with it.
  defp ring_options(opts) do
    {ring, opts} = Keyword.split(opts, [:aim, :split])

    case {ring, opts[:strategy]} do
      {[], _} ->
        {:ok, opts}

      {ring, strategy} when strategy in [nil, :ring] ->
        {:ok, Keyword.put(opts, :strategy, {:ring, ring})}

      {[{flag, _} | _], strategy} ->
        {:usage, "--#{flag} is the ring's own option, not for --strategy #{strategy}"}
    end
  end

  defp preview(render_opts, opts) do
    case opts[:preview] do
      nil ->
        render_opts

      # its address on this command's stderr: a served render's goes to its client
      port ->
        preview = [port: port, announce: Console.err()] ++ Keyword.take(opts, [:listen])
        Keyword.put(render_opts, :preview, preview)
    end
  end

  defp nodes(opts) do
    case opts[:nodes] do
      nil ->
        opts

      text ->
        list = text |> String.split(",", trim: true) |> Enum.map(&String.to_atom(String.trim(&1)))
        Keyword.put(opts, :nodes, list)
    end
  end

  defp choice(opts, key, choices) do
    case opts[key] do
      nil ->
        {:ok, opts}

      name ->
        case Enum.find(choices, &(Atom.to_string(&1) == name)) do
          nil ->
            {:usage, "#{Args.flag(key)} takes one of #{Enum.join(choices, ", ")}, got: #{name}"}

          choice ->
            {:ok, Keyword.put(opts, key, choice)}
        end
    end
  end

  # Four numbers; with a decimal point they are fractions of the image.
  defp region(opts) do
    case opts[:region] do
      nil ->
        {:ok, opts}

      text ->
        parts = text |> String.split(",") |> Enum.map(&String.trim/1)
        fractions? = Enum.any?(parts, &String.contains?(&1, "."))
        parse = if fractions?, do: &Float.parse/1, else: &Integer.parse/1

        values =
          for p <- parts do
            case parse.(p) do
              {v, ""} -> if fractions?, do: v / 1, else: v
              _ -> nil
            end
          end

        if length(values) == 4 and nil not in values,
          do: {:ok, Keyword.put(opts, :region, List.to_tuple(values))},
          else:
            {:usage,
             "--region takes X0,Y0,X1,Y1 in pixels (0,0,320,240) or fractions (0.25,0,0.75,0.5), got: #{text}"}
    end
  end

  defp speeds(opts) do
    case opts[:speeds] do
      nil ->
        {:ok, opts}

      text ->
        parsed =
          for part <- String.split(text, ",") do
            case Float.parse(String.trim(part)) do
              {f, ""} -> if Slowdown.factor?(f), do: if(f == trunc(f), do: trunc(f), else: f)
              _ -> nil
            end
          end

        if parsed != [] and nil not in parsed,
          do: {:ok, Keyword.put(opts, :speeds, parsed)},
          else:
            {:usage,
             "--speeds takes numbers from 1 to #{Slowdown.max()} separated by commas, got: #{text}"}
    end
  end

  defp go(job) do
    t_load = System.monotonic_time(:microsecond)

    with {:ok, scene} <- error_text(RingTracer.Scene.load(job.scene, allow_dirs: job.allow_dirs)),
         load_us = System.monotonic_time(:microsecond) - t_load,
         :ok <- not_interrupted(),
         {:ok, plan} <- Frames.plan(job.opts, job.out, scene.frames, scene.source.name),
         :ok <- one_frame_only(plan, job.opts),
         paths = Enum.map(plan.numbers, &Frames.path(plan, &1)),
         :ok <- usage_text(RingTracer.Output.check_targets(:image, paths)),
         others = Enum.reject(job.outputs, &match?({:image, _}, &1)),
         outputs = others ++ Enum.map(paths, &{:image, &1}),
         :ok <- usage_text(RingTracer.Output.check_inputs(outputs, scene.files)),
         {:ok, dir} <- error_text(RingTracer.Output.open_dir(Path.dirname(hd(paths)))),
         {:ok, numbers} <- to_render(plan, dir, job.opts),
         :ok <- warn(scene) do
      if plan.sequence? do
        RingTracer.CLI.Sequence.run(scene, job, plan, numbers, dir, load_us)
      else
        [n] = numbers
        render_opts = Keyword.put(job.render_opts, :frame, n)
        one(scene, %{job | out: Frames.path(plan, n), render_opts: render_opts}, load_us)
      end
    end
    |> case do
      :ok -> :ok
      {:done, text} -> done(text, job.opts[:quiet])
      {:usage, message} -> usage(message)
      {:interrupted, signal} -> interrupted(signal)
      {:interrupted, signal, written} -> interrupted(signal, written)
      {:error, message} -> failed(message)
    end
  end

  defp done(text, quiet?) do
    if !quiet?, do: IO.write(text)
    :ok
  end

  # One frame: rendered, then its image and reports written, all or none.
  defp one(scene, job, load_us) do
    with {:ok, result} <- render(scene, job),
         # an interrupt while the job ended: nothing is written yet, so nothing is
         :ok <- not_interrupted(),
         :ok <- write_all(result, job) do
      if !job.opts[:quiet], do: IO.write(report(job, result, load_us))
      :ok
    end
  end

  # What draws or traces one image cannot be asked of a sequence.
  defp one_frame_only(%Frames{sequence?: false}, _opts), do: :ok

  defp one_frame_only(plan, opts) do
    n = length(plan.numbers)

    cond do
      opts[:ownership] ->
        {:usage,
         "--ownership tints one frame's image, not a sequence of #{n} frames " <>
           "(give --frame F with it)"}

      opts[:region] ->
        {:usage,
         "--region traces part of one frame, not a sequence of #{n} frames " <>
           "(give --frame F with it)"}

      opts[:aim] ->
        {:usage,
         "--aim aims a ring's offers within one image, not a sequence of #{n} frames " <>
           "(leave it out, or give --frame F with it)"}

      true ->
        :ok
    end
  end

  # `--continue`: the frames whose file is not there yet, whole (written
  # atomically, a file at its final name is complete).
  defp to_render(plan, dir, opts) do
    if opts[:continue], do: continue(plan, dir, opts[:quiet]), else: {:ok, plan.numbers}
  end

  defp continue(plan, dir, quiet?) do
    n = length(plan.numbers)
    say = fn text -> if !quiet?, do: IO.write(text) end

    case Frames.done(plan, dir) do
      {[], left} ->
        if plan.sequence?, do: say.("--continue: none of the #{n} frames written yet\n")
        {:ok, left}

      {[_ | _], []} when n == 1 ->
        {:done,
         "--continue: #{Frames.path(plan, hd(plan.numbers))} is already written; nothing to render\n"}

      {[_ | _], []} ->
        {:done, "--continue: all #{n} frames are already written; nothing to render\n"}

      {done, left} ->
        say.(
          "--continue: skipping #{length(done)} of #{n} frames already written, " <>
            "rendering #{length(left)}\n"
        )

        {:ok, left}
    end
  end

  # What parsed but may not render as meant, before the render (it goes on).
  defp warn(scene) do
    for line <- RingTracer.Scene.Warning.lines(scene.warnings, scene.warnings_omitted),
        do: IO.puts(Console.err(), line)

    :ok
  end

  defp error_text({:error, %RingTracer.Error{message: message}}), do: {:error, message}
  defp error_text(ok), do: ok

  defp usage_text({:error, %RingTracer.Error{message: message}}), do: {:usage, message}
  defp usage_text(ok), do: ok

  defp not_interrupted do
    case RingTracer.CLI.Signals.pending() do
      nil -> :ok
      signal -> {:interrupted, signal}
    end
  end

  defp interrupted(signal) do
    what = if signal == :sigint, do: "interrupted", else: "terminated"
    {:error, RingTracer.CLI.Signals.exit_status(signal), "#{what}; nothing written"}
  end

  # A sequence's frames are written as they arrive: those are whole and stay.
  defp interrupted(signal, 0), do: interrupted(signal)

  defp interrupted(signal, written) do
    what = if signal == :sigint, do: "interrupted", else: "terminated"
    frames = if written == 1, do: "1 frame", else: "#{written} frames"

    {:error, RingTracer.CLI.Signals.exit_status(signal),
     "#{what}; #{frames} written, whole (--continue renders the rest)"}
  end

  # Every output or none: one that cannot be written puts back those
  # written before it.
  defp write_all(result, job) do
    o = job.opts
    # new files as the caller's umask makes them, also through the server
    mode = [mode: Console.new_file_mode()]

    writes =
      [
        {job.out, &RingTracer.Image.write(result, &1, &2)},
        {o[:stats], &RingTracer.Report.Stats.write(result, &1, &2)},
        {o[:timeline], &RingTracer.Report.Timeline.write(result, &1, &2)},
        {o[:ownership], &RingTracer.Report.Ownership.write(result, &1, &2)}
      ]
      |> Enum.reject(fn {path, _} -> path == nil end)
      # each written in the folder write_all/1 opened once and kept its old file in
      |> Enum.map(fn {path, write} -> {path, fn dir -> write.(path, [in: dir] ++ mode) end} end)

    case RingTracer.Output.write_all(writes) do
      :ok -> :ok
      {:error, %RingTracer.Error{message: message}} -> {:error, message <> "; nothing written"}
    end
  end

  # The job runs asynchronously: atoms feed the progress display (through
  # the job's telemetry events), ticks redraw it, and an interrupt cancels
  # the job and ends the command.
  defp render(scene, job) do
    me = self()
    handler = {__MODULE__, make_ref()}
    total = job.render_opts |> Keyword.get(:children, :erlang.system_info(:schedulers_online))

    :ok =
      RingTracer.Telemetry.attach(
        handler,
        [:ring_tracer, :atom, :stop],
        fn _e, m, md, _ -> send(me, {handler, md.job, m.rays, md.total}) end,
        nil
      )

    try do
      {:ok, handle} = RingTracer.render_async(scene, job.render_opts)
      now = System.monotonic_time(:millisecond)

      progress =
        Progress.new(
          job.mode,
          total * Keyword.get(job.render_opts, :atoms, RingTracer.Options.default(:atoms)),
          now
        )

      schedule(job.mode)
      await(handle, handler, progress)
    after
      RingTracer.Telemetry.detach(handler)
    end
  end

  defp schedule(mode) do
    case Progress.interval(mode) do
      nil -> :ok
      ms -> Process.send_after(self(), {__MODULE__, :tick}, ms)
    end
  end

  defp await(handle, handler, progress) do
    id = handle.id

    receive do
      {^handler, _job, rays, total} ->
        progress = %{progress | total: total}
        {progress, _} = Progress.atom(progress, rays, System.monotonic_time(:millisecond))
        await(handle, handler, progress)

      {__MODULE__, :tick} ->
        {progress, text} = Progress.tick(progress, System.monotonic_time(:millisecond))
        if text, do: IO.write(Console.err(), text)
        schedule(progress.mode)
        await(handle, handler, progress)

      {RingTracer, ^id, {:progress, _, _}} ->
        await(handle, handler, progress)

      {RingTracer.CLI.Signals, signal} ->
        IO.write(Console.err(), Progress.finish(progress))
        :ok = RingTracer.CLI.Signals.cancel(handle)
        {:interrupted, signal}

      {RingTracer, ^id, result} ->
        IO.write(Console.err(), Progress.finish(progress))

        case result do
          {:ok, r} ->
            {:ok, r}

          # an option the render refused before any work: a usage error, in the CLI's words
          {:error, %RingTracer.Error{reason: :invalid_option, message: message}} ->
            {:usage, cli_names(message)}

          {:error, %RingTracer.Error{message: message}} ->
            {:error, message}
        end
    end
  end

  @doc false
  # `:children` as the command line spells it: `--children`.
  @spec cli_names(String.t()) :: String.t()
  def cli_names(message) do
    Regex.replace(~r/(?<![\w:]):([a-z][a-z_]*)\b/, message, fn _, name ->
      "--" <> String.replace(name, "_", "-")
    end)
  end

  @doc false
  # POV-Ray-style statistics: what was written, then `RingTracer.CLI.Report`'s.
  @spec report(map(), RingTracer.Result.t(), non_neg_integer()) :: iodata()
  def report(job, result, load_us) do
    [
      "wrote #{job.out} (#{result.width}x#{result.height})\n",
      RingTracer.CLI.Report.statistics(result, load_us),
      RingTracer.CLI.Report.reports_written(job.opts)
    ]
  end
end
