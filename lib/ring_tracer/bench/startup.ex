defmodule RingTracer.Bench.Startup do
  @help """
  The whole command against POV-Ray's whole process.

      mix ring_tracer.bench startup [--scenes a,b] [--runs 5] [--size 512]

  Runs `bin/ringtracer render SCENE` at `--size` (quiet, with `--stats`),
  and POV-Ray's whole process on the matching `.pov`, alternately, and
  prints for each SPD scene the time from exec to the first atom's pixels
  (from the job's `started_at_us` and first atom in the statistics), both
  whole-process times and their ratio.
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.Bench.PovRay

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "startup [--scenes a,b] [--runs 5] [--size 512]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [scenes: :string, dir: :string, pov_dir: :string, runs: :integer, size: :integer]
      )

    dir = opts[:dir] || "priv/scenes/spd"
    pov_dir = opts[:pov_dir] || PovRay.default_dir()
    scenes = if s = opts[:scenes], do: String.split(s, ","), else: PovRay.spd_scenes()
    runs = opts[:runs] || 5
    size = opts[:size] || 512
    povray = PovRay.executable()
    launcher = Path.expand("bin/ringtracer")
    tmp = Path.join(System.tmp_dir!(), "ring_tracer_bench_startup")
    File.mkdir_p!(tmp)
    # The launcher builds itself first if it is stale: not part of any run.
    {_, 0} = System.cmd(launcher, ["render", "--help"], stderr_to_stdout: true)

    info(
      "#{size}x#{size}, whole processes, median of #{runs} (alternating); " <>
        "first atom: from exec to the first atom's pixels reaching the parent; " <>
        "povray +WT2 -D -A" <> if(povray, do: "", else: " (povray not installed)")
    )

    header = ~w(scene first_atom_s ours_s pov_s ours/pov)

    rows =
      for name <- scenes do
        scene = Path.expand(Path.join(dir, name <> ".nff"))
        pov = Path.expand(Path.join(pov_dir, name <> ".pov"))

        ours = fn ->
          stats = Path.join(tmp, "stats.json")

          args =
            ~w(render #{scene} -o #{tmp}/ours.png --width #{size} --height #{size} -q --stats #{stats})

          t0 = System.system_time(:microsecond)
          {_, 0} = System.cmd(launcher, args, stderr_to_stdout: true)
          whole = System.system_time(:microsecond) - t0
          summary = stats |> File.read!() |> :jiffy.decode([:return_maps])
          {whole, summary["started_at_us"] + summary["first_atom_us"] - t0}
        end

        theirs = fn ->
          if povray && File.exists?(pov) do
            t0 = System.monotonic_time(:microsecond)

            {_, _} =
              System.cmd(
                povray,
                ~w(+I#{pov} +O#{tmp}/pov.png +W#{size} +H#{size} -D -A +WT2),
                stderr_to_stdout: true
              )

            System.monotonic_time(:microsecond) - t0
          end
        end

        samples = for _ <- 1..runs, do: {ours.(), theirs.()}
        whole = median(Enum.map(samples, fn {{w, _}, _} -> w end))
        first = median(Enum.map(samples, fn {{_, f}, _} -> f end))
        pov_samples = for {_, p} <- samples, p != nil, do: p
        pov_us = if pov_samples != [], do: median(pov_samples)

        [
          name,
          secs(first),
          secs(whole),
          pov_us && secs(pov_us),
          pov_us && fmt(whole / pov_us)
        ]
      end

    print_table(header, rows)
  end
end
