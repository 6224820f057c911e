defmodule RingTracer.Bench.Kernel do
  @help """
  The kernel against POV-Ray, and the ring against the kernel.

      mix ring_tracer.bench kernel [--scenes a,b] [--dir DIR] [--pov-dir DIR] [--runs R]
                                   [--size 512] [--threads 2] [--children 8] [--atoms 16]
                                   [--fixed]

  For each SPD scene (default: the standard sizes in `priv/scenes/spd`):
  our set-up time (read, parse, BVH) and trace time with the kernel's own
  `--threads` threads; POV-Ray 3.7's parse and trace times for the matching
  `.pov` file (`povray +W512 +H512 -D -A +WT2`, when `povray` is installed and
  the `.pov` is in `--pov-dir`, by default `../shared/scenes/spd/pov`); the
  same render through the ring with `--children` children; and the ratios
  ours/POV-Ray and ring/kernel; and the trace's CPU time, ours (the VM's OS
  process while the kernel renders) and POV-Ray's (its report's
  CPU-seconds of the trace threads), with their ratio, which other programs
  sharing the cores move much less than the wall-clock times. Times are medians of `--runs` runs (default 3);
  kernel and ring renders alternate, and ring/kernel is the median of the
  pairs' ratios, so that both see the same drift in this machine's speed.
  `ring-kernel_ms` is the ring's fixed cost in milliseconds (the median of
  the pairs' differences), which stays meaningful as the kernel gets faster;
  the header gives the floor under it, one dirty kernel call's cost
  (`nif_call_us/1`), paid once per atom; `--fixed` adds where the fixed
  cost goes (`fixed_costs/4`).
  Depth 5, one ray per pixel centre, adaptive cut-off at its default, as
  POV-Ray's own `Max Level 5` and ADC bailout do.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.{Native, Rays, Scene, SceneCache, Settings}
  alias RingTracer.Bench.PovRay

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage,
    do:
      "kernel [--scenes a,b] [--dir DIR] [--pov-dir DIR] [--runs R] [--size 512] " <>
        "[--threads 2] [--children 8] [--atoms 16] [--fixed]"

  @impl RingTracer.Bench
  def run(argv) do
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
          atoms: :integer,
          fixed: :boolean
        ]
      )

    Mix.Task.run("app.start")
    dir = opts[:dir] || "priv/scenes/spd"
    pov_dir = opts[:pov_dir] || PovRay.default_dir()
    scenes = if s = opts[:scenes], do: String.split(s, ","), else: PovRay.spd_scenes()
    runs = opts[:runs] || 3
    size = opts[:size] || 512
    threads = opts[:threads] || 2
    children = opts[:children] || 8
    atoms = opts[:atoms] || 16
    povray = PovRay.executable()

    info(
      "#{size}x#{size}, depth 5, #{threads} kernel threads, ring of #{children} children x #{atoms} atoms, " <>
        "median of #{runs}; #{vm()}" <>
        if(povray, do: "", else: "; povray not installed (apt-get install povray)")
    )

    info("one dirty kernel call of one pixel: #{fmt(nif_call_us())} us (median of 200)")

    header =
      ~w(scene setup_s trace_s Mrays/s pov_parse_s pov_trace_s ours/pov trace_cpu_s pov_cpu_s cpu_ours/pov ring_s ring/kernel ring-kernel_ms)

    rows =
      for name <- scenes do
        path = Path.join(dir, name <> ".nff")
        {setup_us, {:ok, scene}} = :timer.tc(fn -> Scene.load(path) end)
        :ok = SceneCache.put(scene)
        settings = %Settings{width: size, height: size}
        native = Settings.to_native(settings)

        # Wall time, and the CPU time of the VM's OS process meanwhile (the
        # kernel's threads; the VM is otherwise idle).
        kernel = fn ->
          cpu0 = Native.process_cpu_us()

          {us, {:ok, {_pixels, rays}}} =
            :timer.tc(fn -> Native.render_image(scene.ref, native, threads) end)

          {us, rays, Native.process_cpu_us() - cpu0}
        end

        ring = fn ->
          {:ok, result} =
            RingTracer.render(path, children: children, atoms: atoms, width: size, height: size)

          result.elapsed_us
        end

        # Kernel and ring alternate, so that both see the same drift of this
        # machine's speed; ring/kernel is the median of the pairs' ratios.
        {:ok, _} = RingTracer.render(path, children: children, atoms: 1, width: 8, height: 8)
        pairs = for _ <- 1..runs, do: {kernel.(), ring.()}
        {_, rays, _} = pairs |> List.last() |> elem(0)
        trace_us = median(Enum.map(pairs, fn {{k, _, _}, _} -> k end))
        cpu_us = median(Enum.map(pairs, fn {{_, _, c}, _} -> c end))
        ring_us = median(Enum.map(pairs, fn {_, r} -> r end))
        ring_ratio = median(Enum.map(pairs, fn {{k, _, _}, r} -> r / k end))
        fixed_us = median(Enum.map(pairs, fn {{k, _, _}, r} -> r - k end))

        pov = PovRay.times(povray, Path.join(pov_dir, name <> ".pov"), size, threads, runs)

        [
          name,
          secs(setup_us),
          secs(trace_us),
          fmt(Rays.total(rays) / trace_us),
          pov && secs(pov.parse_us),
          pov && secs(pov.trace_us),
          pov && fmt(trace_us / max(pov.trace_us, 1)),
          secs(cpu_us),
          pov && secs(pov.trace_cpu_us),
          pov && fmt(cpu_us / max(pov.trace_cpu_us, 1)),
          secs(ring_us),
          fmt(ring_ratio),
          fmt(fixed_us / 1000)
        ]
      end

    print_table(header, rows)

    if opts[:fixed] do
      path = Path.join(dir, hd(scenes) <> ".nff")

      info(
        "\nwhere a job's fixed cost goes (#{hd(scenes)} at 64x64, where tracing is " <>
          "negligible; #{children} children x #{atoms} atoms; medians of #{max(runs, 15)}; ms):"
      )

      print_table(
        ~w(part ms),
        Enum.map(fixed_costs(path, children, atoms, max(runs, 15)), fn {part, us} ->
          [part, fmt(us / 1000)]
        end)
      )
    end
  end

  @doc """
  Where the ring's fixed cost per job goes, on a `children` x `atoms` job
  of a 64x64 image of the scene at `path` (tracing is then a small part
  of the makespan): the makespans of `static` with one atom per child and
  with `atoms`, of the ring without and with aiming, compared, each the
  median of `runs` (the four alternate). In microseconds:

    * `"start-up"`: from the job's start to its first atom's start;
    * `"per atom"`: what one more atom adds to the makespan, no protocol
      (`static`'s difference over the extra atoms): the kernel call's
      boundary and the atom's messages;
    * `"atoms"`: that, times the job's atoms;
    * `"ring protocol"`: the ring without aiming over `static`;
    * `"work preview"`: the ring with aiming over the ring without;
    * `"end"`: from the last atom's end to the parent holding every atom.
  """
  @spec fixed_costs(Path.t(), pos_integer(), pos_integer(), pos_integer()) ::
          [{String.t(), number()}]
  def fixed_costs(path, children, atoms, runs) do
    {:ok, scene} = Scene.load(path)
    job = [children: children, atoms: atoms, width: 64, height: 64]

    jobs = [
      one: [strategy: :static, atoms: 1],
      static: [strategy: :static],
      ring: [strategy: {:ring, aim: false}],
      aimed: [strategy: {:ring, aim: true}]
    ]

    render = fn how -> elem(RingTracer.render(scene, Keyword.merge(job, how)), 1) end
    Enum.each(jobs, fn {_, how} -> render.(how) end)

    results =
      for _ <- 1..runs, {name, how} <- jobs do
        r = render.(how)
        first = r.atoms |> Enum.map(& &1.start_us) |> Enum.min()
        last = r.atoms |> Enum.map(& &1.end_us) |> Enum.max()
        {name, %{elapsed: r.elapsed_us, first: first, end: r.elapsed_us - last}}
      end

    m = fn name, key ->
      results |> Enum.filter(&(elem(&1, 0) == name)) |> Enum.map(&elem(&1, 1)[key]) |> median()
    end

    per_atom =
      if atoms > 1,
        do: (m.(:static, :elapsed) - m.(:one, :elapsed)) / (children * (atoms - 1)),
        else: 0

    [
      {"start-up", m.(:ring, :first)},
      {"per atom", per_atom},
      {"atoms", per_atom * children * atoms},
      {"ring protocol", m.(:ring, :elapsed) - m.(:static, :elapsed)},
      {"work preview", m.(:aimed, :elapsed) - m.(:ring, :elapsed)},
      {"end", m.(:ring, :end)}
    ]
  end

  @doc """
  The median wall time, in microseconds, of a kernel call
  (`RingTracer.Native.trace_atom/4` on a dirty CPU scheduler) that traces
  one pixel (of an 8x8 image of `path`): what every atom costs beyond its
  tracing, mostly waking a sleeping dirty scheduler thread.
  """
  @spec nif_call_us(Path.t()) :: float()
  def nif_call_us(path \\ "priv/scenes/spd/tetra_s6.nff") do
    {:ok, scene} = Scene.load(path)
    native = Settings.to_native(%Settings{width: 8, height: 8})

    for(_ <- 1..200, do: elem(:timer.tc(fn -> Native.trace_atom(scene.ref, native, 0, 1) end), 0))
    |> median()
    |> Kernel./(1)
  end
end
