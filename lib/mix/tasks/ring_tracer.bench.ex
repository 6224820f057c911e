defmodule Mix.Tasks.RingTracer.Bench do
  @shortdoc "Benchmarks: the kernel against POV-Ray, and the ring against the kernel"
  @moduledoc """
  Benchmarks that print figures side by side from one run.

      mix ring_tracer.bench kernel [--scenes a,b] [--dir DIR] [--pov-dir DIR] [--runs R]
                                   [--size 512] [--threads 2] [--children 8] [--atoms 16]

  For each SPD scene (default: the standard sizes in `priv/scenes/spd`):
  our set-up time (read, parse, BVH) and trace time with the kernel's own
  `--threads` threads; POV-Ray 3.7's parse and trace times for the matching
  `.pov` file (`povray +W512 +H512 -D -A +WT2`, when `povray` is installed and
  the `.pov` is in `--pov-dir`, by default `../shared/scenes/spd/pov`); the
  same render through the ring with `--children` children; and the ratios
  ours/POV-Ray and ring/kernel. Times are medians of `--runs` runs (default 3).
  Depth 5, one ray per pixel centre, adaptive cut-off at its default, as
  POV-Ray's own `Max Level 5` and ADC bailout do.
  """
  use Mix.Task

  alias RingTracer.{Native, Scene, SceneCache, Settings}

  @spd ~w(balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11)

  @impl Mix.Task
  def run(["kernel" | argv]) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [
          scenes: :string,
          dir: :string,
          pov_dir: :string,
          runs: :integer,
          size: :integer,
          threads: :integer,
          children: :integer,
          atoms: :integer
        ]
      )

    Mix.Task.run("app.start")
    dir = opts[:dir] || "priv/scenes/spd"
    pov_dir = opts[:pov_dir] || "../shared/scenes/spd/pov"
    scenes = if s = opts[:scenes], do: String.split(s, ","), else: @spd
    runs = opts[:runs] || 3
    size = opts[:size] || 512
    threads = opts[:threads] || 2
    children = opts[:children] || 8
    atoms = opts[:atoms] || 16
    povray = System.find_executable("povray")

    Mix.shell().info(
      "#{size}x#{size}, depth 5, #{threads} kernel threads, ring of #{children} children x #{atoms} atoms, " <>
        "median of #{runs}; #{System.schedulers_online()} schedulers, " <>
        "#{:erlang.system_info(:dirty_cpu_schedulers_online)} dirty CPU schedulers" <>
        if(povray, do: "", else: "; povray not installed (apt-get install povray)")
    )

    header = ~w(scene setup_s trace_s Mrays/s pov_parse_s pov_trace_s ours/pov ring_s ring/kernel)

    rows =
      for name <- scenes do
        path = Path.join(dir, name <> ".nff")
        {setup_us, {:ok, scene}} = :timer.tc(fn -> Scene.load(path) end)
        :ok = SceneCache.put(scene)
        settings = %Settings{width: size, height: size}
        native = Settings.to_native(settings)

        {trace_us, rays} =
          median_run(runs, fn ->
            {:ok, {_pixels, rays}} = Native.render_image(scene.ref, native, threads)
            rays
          end)

        total_rays = rays.eye + rays.reflected + rays.refracted + rays.shadow

        {ring_us, _} =
          median_run(runs, fn ->
            {:ok, result} =
              RingTracer.render(path, children: children, atoms: atoms, width: size, height: size)

            result.elapsed_us
          end)

        pov = pov_times(povray, Path.join(pov_dir, name <> ".pov"), size, threads, runs)

        [
          name,
          secs(setup_us),
          secs(trace_us),
          fmt(total_rays / trace_us),
          pov && secs(pov.parse_us),
          pov && secs(pov.trace_us),
          pov && fmt(trace_us / max(pov.trace_us, 1)),
          secs(ring_us),
          fmt(ring_us / trace_us)
        ]
      end

    print_table(header, rows)
  end

  def run(_),
    do:
      Mix.raise("usage: mix ring_tracer.bench kernel [options]  (see mix help ring_tracer.bench)")

  # Runs `fun` `runs` times; the median of its time (or, if it returns an
  # integer of microseconds, that) with the last value it returned.
  defp median_run(runs, fun) do
    samples =
      for _ <- 1..runs do
        {us, value} = :timer.tc(fun)
        if is_integer(value), do: {value, value}, else: {us, value}
      end

    sorted = Enum.sort_by(samples, &elem(&1, 0))
    {elem(Enum.at(sorted, div(runs, 2)), 0), elem(List.last(samples), 1)}
  end

  defp pov_times(nil, _file, _size, _threads, _runs), do: nil

  defp pov_times(povray, file, size, threads, runs) do
    if File.exists?(file) do
      samples =
        for _ <- 1..runs do
          out = Path.join(System.tmp_dir!(), "ring_tracer_bench_pov.png")

          {text, _} =
            System.cmd(
              povray,
              [
                "+I#{file}",
                "+O#{out}",
                "+W#{size}",
                "+H#{size}",
                "-D",
                "-A",
                "+WT#{threads}"
              ],
              stderr_to_stdout: true
            )

          %{
            parse_us: seconds(text, "Parse Time") + seconds(text, "Bounding Time"),
            trace_us: seconds(text, "Trace Time")
          }
        end

      %{
        parse_us: median(Enum.map(samples, & &1.parse_us)),
        trace_us: median(Enum.map(samples, & &1.trace_us))
      }
    end
  end

  defp seconds(text, label) do
    case Regex.run(~r/#{label}:[^(]*\(([0-9.]+) seconds\)/, text) do
      [_, s] -> round(String.to_float(s) * 1_000_000)
      nil -> 0
    end
  end

  defp median(list), do: Enum.at(Enum.sort(list), div(length(list), 2))
  defp secs(us), do: fmt(us / 1_000_000)
  defp fmt(x), do: :erlang.float_to_binary(x / 1, decimals: 3)

  defp print_table(header, rows) do
    rows = Enum.map(rows, fn r -> Enum.map(r, &(&1 || "-")) end)

    widths =
      Enum.map(Enum.zip([header | rows]), fn col ->
        col |> Tuple.to_list() |> Enum.map(&String.length/1) |> Enum.max()
      end)

    for row <- [header | rows] do
      row
      |> Enum.zip(widths)
      |> Enum.map_join("  ", fn {cell, w} -> String.pad_leading(cell, w) end)
      |> Mix.shell().info()
    end
  end
end
