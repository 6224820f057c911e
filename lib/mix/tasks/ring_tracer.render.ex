defmodule Mix.Tasks.RingTracer.Render do
  @shortdoc "Renders a scene through the ring and writes an image"
  @moduledoc """
  Renders a scene file through a ring of children and writes the image.

      mix ring_tracer.render SCENE --out FILE [options]

  `FILE` ends in `.png` (8-bit sRGB) or `.exr` (linear float).

  ## Options

    * `--out FILE` — where to write the image (required)
    * `--children N` — ring size (default: schedulers online)
    * `--atoms K` — atoms per child (default 16)
    * `--width W`, `--height H` — image size (default: the scene's)
    * `--depth D` — ray-tree depth limit, eye ray = 1 (default 5)
    * `--cutoff C` — adaptive cut-off weight (default 1/255, 0 disables)
    * `--samples S` — S x S samples per pixel (default 1)
    * `--spd` — the SPD testing procedure (pixel corners, no cut-off)
    * `--strategy S` — `ring` (default), `static`, `master` or `steal`
    * `--layout L` — `strips` (the paper's contiguous strips, default) or
      `interleaved` (child i owns atoms i, i + N, i + 2N, ...)
    * `--aim` / `--no-aim` — ring only: idle children send their offers
      straight to the sibling expected to stay busy longest (default: on
      strips yes, on interleaved strips no)
    * `--speeds 1,1,4,1` — slowdown factor of each child (cyclic)
    * `--stats FILE` — the job's statistics as `.json` or `.csv`
    * `--timeline FILE.svg` — one lane per child, every atom a bar coloured
      by its original owner, help offers as arrows
    * `--ownership FILE.png` — the image tinted by the child that traced each atom

  Across nodes (see `mix ring_tracer.worker` to start them):

    * `--nodes a@host,b@host` — also place children on these nodes (round robin)
    * `--children-per-node C` — C children on each node instead
    * `--no-local` — no children on this node
    * `--sname NAME` / `--name NAME@HOST` — this node's name (a unique short
      name is made up when `--nodes` is given without one; a node started
      with `elixir --sname X -S mix ...` is used as is)
    * `--cookie-file PATH` — the cookie, in a file only you can read
      (default `~/.erlang.cookie`)
    * `--listen ADDR`, `--ports MIN-MAX` — where this node listens (default
      127.0.0.1, any port)
    * `--tls DIR` — distribution over TLS (see `RingTracer.Cluster.TLS`)

  Files:

    * `--allow-dir DIR` — a folder (besides the scene's own) that the scene
      may read meshes and materials from; repeatable

  Every output is checked before any tracing (extension, folder, no two the
  same file, none an input of the render) and written atomically.

  A progress bar (atoms done / total, rate, ETA) goes to stderr when it is a
  terminal.

  Before rendering, prints the scene's warnings to stderr, one per line as
  `file:line: warning: message` (what parsed but may not render as meant,
  see `RingTracer.Scene.Warning`); the render goes on.

  Prints where it wrote the image, the job's time, the ray counts and a line
  per child.
  """
  use Mix.Task

  alias RingTracer.CLI.Paths

  @switches [
              out: :string,
              children: :integer,
              atoms: :integer,
              width: :integer,
              height: :integer,
              depth: :integer,
              cutoff: :float,
              samples: :integer,
              spd: :boolean,
              strategy: :string,
              layout: :string,
              aim: :boolean,
              speeds: :string,
              stats: :string,
              timeline: :string,
              ownership: :string,
              nodes: :string,
              children_per_node: :integer,
              local: :boolean,
              allow_dir: :keep
            ] ++ RingTracer.CLI.Worker.switches()

  @outputs [out: :image, stats: :stats, timeline: :timeline, ownership: :ownership]
  @distribution Keyword.keys(RingTracer.CLI.Worker.switches())

  @impl Mix.Task
  def run(argv) do
    {opts, args, invalid} = OptionParser.parse(argv, strict: @switches, aliases: [o: :out])

    if invalid != [] do
      Mix.raise("invalid option(s): #{Enum.map_join(invalid, ", ", &elem(&1, 0))}")
    end

    scene =
      case args do
        [scene] -> Paths.expand(scene)
        _ -> Mix.raise("usage: mix ring_tracer.render SCENE --out FILE [options]")
      end

    ok!(RingTracer.Cluster.Distribution.refuse_cookie(opts))

    opts =
      Paths.expand(opts, [:out, :stats, :timeline, :ownership, :cookie_file, :tls, :allow_dir])

    out = opts[:out] || Mix.raise("--out FILE is required (a .png or .exr file)")
    outputs = for {key, kind} <- @outputs, path = opts[key], do: {kind, path}
    # Outputs first: a bad one is known before the scene is even read.
    ok!(RingTracer.Output.check(outputs, [scene]))

    if opts[:nodes] do
      ok!(
        RingTracer.Cluster.Distribution.start(
          Keyword.take(opts, @distribution) ++ [generate: true]
        )
      )
    end

    Mix.Task.run("app.start")
    allow_dirs = Keyword.get_values(opts, :allow_dir)

    render_opts =
      opts
      |> Keyword.drop([:out, :stats, :timeline, :ownership, :allow_dir | @distribution])
      |> parse_nodes()
      |> parse_choice(:strategy, RingTracer.Strategy.names())
      |> parse_choice(:layout, RingTracer.Layout.orders())
      |> parse_speeds()

    # Then the scene, whose references are inputs too; then the job.
    {:ok, loaded} = ok!(RingTracer.Scene.load(scene, allow_dirs: allow_dirs))
    ok!(RingTracer.Output.check_inputs(outputs, loaded.files))

    for line <- RingTracer.Scene.Warning.lines(loaded.warnings, loaded.warnings_omitted),
        do: IO.puts(:stderr, line)

    with {:ok, result} <- render(loaded, render_opts),
         :ok <- RingTracer.Image.write(result, out),
         :ok <- maybe_write(opts[:stats], &RingTracer.Report.Stats.write(result, &1)),
         :ok <- maybe_write(opts[:timeline], &RingTracer.Report.Timeline.write(result, &1)),
         :ok <- maybe_write(opts[:ownership], &RingTracer.Report.Ownership.write(result, &1)) do
      report(out, result)

      for {key, path} <- opts,
          key in [:stats, :timeline, :ownership],
          do: Mix.shell().info("wrote #{path}")
    else
      {:error, %RingTracer.Error{message: message}} -> Mix.raise(message)
    end
  end

  defp ok!({:error, %RingTracer.Error{message: message}}), do: Mix.raise(message)
  defp ok!(ok), do: ok

  defp maybe_write(nil, _fun), do: :ok
  defp maybe_write(path, fun), do: fun.(path)

  defp parse_nodes(opts) do
    case opts[:nodes] do
      nil ->
        opts

      text ->
        Keyword.put(
          opts,
          :nodes,
          text |> String.split(",", trim: true) |> Enum.map(&String.to_atom(String.trim(&1)))
        )
    end
  end

  # `--strategy` and `--layout`: a name among `choices` (atoms), or absent.
  defp parse_choice(opts, key, choices) do
    case opts[key] do
      nil ->
        opts

      name ->
        case Enum.find(choices, &(Atom.to_string(&1) == name)) do
          nil -> Mix.raise("--#{key} must be one of #{Enum.join(choices, ", ")}, got: #{name}")
          choice -> Keyword.put(opts, key, choice)
        end
    end
  end

  defp parse_speeds(opts) do
    case opts[:speeds] do
      nil ->
        opts

      text ->
        speeds =
          for part <- String.split(text, ",", trim: true) do
            case Float.parse(String.trim(part)) do
              {f, ""} -> if f == trunc(f), do: trunc(f), else: f
              _ -> Mix.raise("--speeds takes numbers separated by commas, got: #{text}")
            end
          end

        Keyword.put(opts, :speeds, speeds)
    end
  end

  # Renders asynchronously so that progress can be shown on a terminal.
  defp render(scene, opts) do
    {:ok, job} = RingTracer.render_async(scene, opts)
    tty? = match?({:ok, _}, :io.columns(:standard_error))
    await(job.id, tty?, System.monotonic_time(:millisecond))
  end

  defp await(id, tty?, t0) do
    receive do
      {RingTracer, ^id, {:progress, done, total}} ->
        if tty?, do: progress(done, total, t0)
        await(id, tty?, t0)

      {RingTracer, ^id, result} ->
        if tty?, do: IO.write(:stderr, "\r\e[K")
        result
    end
  end

  defp progress(done, total, t0) do
    elapsed = max(System.monotonic_time(:millisecond) - t0, 1) / 1000
    rate = done / elapsed
    eta = if rate > 0, do: (total - done) / rate, else: 0.0
    width = 30
    filled = div(done * width, max(total, 1))
    bar = String.duplicate("#", filled) <> String.duplicate("-", width - filled)

    IO.write(
      :stderr,
      "\r[#{bar}] #{done}/#{total} atoms  #{:erlang.float_to_binary(rate, decimals: 1)}/s  ETA #{:erlang.float_to_binary(eta, decimals: 1)} s"
    )
  end

  defp report(out, result) do
    r = result.rays

    Mix.shell().info(
      "wrote #{out} (#{result.width}x#{result.height}) in #{format_ms(result.elapsed_us)} " <>
        "with #{length(result.children)} children"
    )

    Mix.shell().info(
      "rays: eye #{r.eye} (hit #{r.eye_hits}), reflected #{r.reflected}, " <>
        "refracted #{r.refracted}, shadow #{r.shadow}; #{r.work} work units"
    )

    for c <- result.children do
      Mix.shell().info(
        "  child #{c.index}#{if c.node != node(), do: " on #{c.node}"}: own #{c.own} given #{c.given} received #{c.received} " <>
          "traced #{c.traced}; offers sent #{c.offers_sent} passed #{c.offers_passed} " <>
          "consumed #{c.offers_consumed}"
      )
    end
  end

  defp format_ms(us), do: :io_lib.format("~.3f s", [us / 1_000_000]) |> IO.iodata_to_binary()
end
