defmodule Mix.Tasks.RingTracer.Bench do
  @shortdoc "Benchmarks: the kernel against POV-Ray, and the ring against the kernel"
  @moduledoc """
  Benchmarks that print figures side by side from one run.

      mix ring_tracer.bench balance [--size 1024] [--atoms 16] [--runs 3] [--quick]

  `balance` renders the same atoms with every strategy (`static`, `master`,
  `ring`, `steal`) on real scenes (4 equal children; 4 with one 4x slower; 8
  with speeds 1..8; SPD tetra and teapot, whose empty background makes static
  strips unequal) and on the simulated kernel with 64, 256 and 1024
  children, and prints makespan / ideal, idle %, and messages and bytes per
  atom (counted at the sender; bytes include the pixels). Each real row is
  the median (by makespan / ideal) of `--runs` renders after one warm-up.
  Each real scenario also runs the ring on interleaved strips
  (`ring/interleaved`, `layout: :interleaved`: child i owns atoms i, i + N,
  ...; see `RingTracer.Layout`), which shows how much of the ring's loss
  comes with the paper's contiguous strips, and every scenario runs it
  once more on strips with every offer sent to the left sibling as in the
  paper (`ring/left`, `aim: false`; see `RingTracer.Strategy.Ring.Aim`). For each real scenario a
  `floor` row runs the same atoms and speeds with no protocol at all (N
  processes calling the kernel, taking atoms from one shared counter): the
  distance from it to 1.0 is this machine's cost of dirty NIF calls, not
  load balancing. Images are 1024x1024 by default: at
  512x512 the real jobs last 20 to 170 ms, and one atom or one scheduling
  hiccup is then several percent of the makespan even for the `floor`.
  Under the table it checks issue 4's targets against it, each "ok" or
  "MISSED".

      mix ring_tracer.bench rays MESH.obj [MORE.obj ...]

  `rays` casts closest-hit rays only, in the kernel alone: 1024 x 1024
  primary rays through a 45-degree pinhole looking at the mesh's bounding-box
  centre from centre + (0.3, 0.3, 1.1) x its diagonal, and 1,048,576
  incoherent rays (fixed seed); prints the BVH build time, Mrays/s with 1
  and 2 threads, and hit counts.

      mix ring_tracer.bench limits [--quick]

  `limits` runs each documented maximum of `RingTracer.Options` and the
  kernel's image size at full size (`--quick`: a sixteenth): 16,384
  children, 1,048,576 atoms (simulated, and real on 64 children), and a 64
  Mpixel image, printing time, the VM's memory growth and the outcome.

      mix ring_tracer.bench startup [--scenes a,b] [--runs 5] [--size 512]

  `startup` runs the whole command, `bin/ringtracer render SCENE` at
  `--size` (quiet, with `--stats`), and POV-Ray's whole process on the
  matching `.pov`, alternately, and prints for each SPD scene the time from
  exec to the first atom's pixels (from the job's `started_at_us` and first
  atom in the statistics), both whole-process times and their ratio.

      mix ring_tracer.bench nodes [--scene FILE] [--children 6] [--runs 3]

  `nodes` starts two peer nodes on this machine and renders the same job on
  this node alone and on all three, printing both makespans, their ratio and
  the scene bytes each node received (shipped once per node).

      mix ring_tracer.bench kernel [--scenes a,b] [--dir DIR] [--pov-dir DIR] [--runs R]
                                   [--size 512] [--threads 2] [--children 8] [--atoms 16]

  For each SPD scene (default: the standard sizes in `priv/scenes/spd`):
  our set-up time (read, parse, BVH) and trace time with the kernel's own
  `--threads` threads; POV-Ray 3.7's parse and trace times for the matching
  `.pov` file (`povray +W512 +H512 -D -A +WT2`, when `povray` is installed and
  the `.pov` is in `--pov-dir`, by default `../shared/scenes/spd/pov`); the
  same render through the ring with `--children` children; and the ratios
  ours/POV-Ray and ring/kernel. Times are medians of `--runs` runs (default 3);
  kernel and ring renders alternate, and ring/kernel is the median of the
  pairs' ratios, so that both see the same drift in this machine's speed.
  Depth 5, one ray per pixel centre, adaptive cut-off at its default, as
  POV-Ray's own `Max Level 5` and ADC bailout do.
  """
  use Mix.Task

  alias RingTracer.{Native, Scene, SceneCache, Settings}
  alias RingTracer.Job.Slowdown

  @sim_atoms 64
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
        "median of #{runs}; #{vm()}" <>
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

        kernel = fn ->
          {us, {:ok, {_pixels, rays}}} =
            :timer.tc(fn -> Native.render_image(scene.ref, native, threads) end)

          {us, rays}
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
        {_, rays} = pairs |> List.last() |> elem(0)
        trace_us = median(Enum.map(pairs, fn {{k, _}, _} -> k end))
        ring_us = median(Enum.map(pairs, fn {_, r} -> r end))
        ring_ratio = median(Enum.map(pairs, fn {{k, _}, r} -> r / k end))
        total_rays = rays.eye + rays.reflected + rays.refracted + rays.shadow

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
          fmt(ring_ratio)
        ]
      end

    print_table(header, rows)
  end

  def run(["startup" | argv]) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [scenes: :string, dir: :string, pov_dir: :string, runs: :integer, size: :integer]
      )

    dir = opts[:dir] || "priv/scenes/spd"
    pov_dir = opts[:pov_dir] || "../shared/scenes/spd/pov"
    scenes = if s = opts[:scenes], do: String.split(s, ","), else: @spd
    runs = opts[:runs] || 5
    size = opts[:size] || 512
    povray = System.find_executable("povray")
    launcher = Path.expand("bin/ringtracer")
    tmp = Path.join(System.tmp_dir!(), "ring_tracer_bench_startup")
    File.mkdir_p!(tmp)
    # The launcher builds itself first if it is stale: not part of any run.
    {_, 0} = System.cmd(launcher, ["render", "--help"], stderr_to_stdout: true)

    Mix.shell().info(
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

  def run(["limits" | argv]) do
    {opts, _, _} = OptionParser.parse(argv, strict: [quick: :boolean])
    Mix.Task.run("app.start")
    max = RingTracer.Options.maxima()
    # --quick: a sixteenth of each, for a check that the command itself works.
    q = if opts[:quick], do: 16, else: 1
    scene = "priv/scenes/balls_s1.nff"
    side = div(8192, if(q == 1, do: 1, else: 4))

    Mix.shell().info(
      "every documented maximum at #{if q == 1, do: "full size", else: "1/#{q} size (--quick)"}; #{vm()}"
    )

    cases = [
      {"children", "#{div(max.children, q)} children x 1 atom, 256x256",
       fn ->
         RingTracer.render(scene,
           children: div(max.children, q),
           atoms: 1,
           width: 256,
           height: 256
         )
       end},
      {"atoms", "1 child x #{div(max.atoms, q)} atoms (simulated, 1 us each)",
       fn -> RingTracer.simulate(children: 1, atoms: div(max.atoms, q), costs: 1) end},
      {"atoms", "64 children x #{div(max.atoms, 64 * q)} atoms, 1024x1024",
       fn ->
         RingTracer.render(scene,
           children: 64,
           atoms: div(max.atoms, 64 * q),
           width: 1024,
           height: 1024
         )
       end},
      {"pixels", "#{side}x#{side} (#{div(side * side, 1_048_576)} Mpixel), 8 children",
       fn ->
         RingTracer.render(scene, children: 8, atoms: 64, width: side, height: side, depth: 2)
       end}
    ]

    rows =
      for {what, job, fun} <- cases do
        :erlang.garbage_collect()
        before = :erlang.memory(:total)
        {us, result} = :timer.tc(fun)

        outcome =
          case result do
            {:ok, r} -> "ok, #{length(r.atoms)} atoms"
            {:error, e} -> "ERROR: #{e.message}"
          end

        peak = :erlang.memory(:total) - before
        [what, job, secs(us), "#{div(max(peak, 0), 1_048_576)} MiB", outcome]
      end

    print_table(~w(maximum job seconds vm_growth outcome), rows)
  end

  def run(["balance" | argv]) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [size: :integer, atoms: :integer, quick: :boolean, runs: :integer]
      )

    Mix.Task.run("app.start")
    size = opts[:size] || 1024
    k = opts[:atoms] || 16
    sims = if opts[:quick], do: [64], else: [64, 256, 1024]
    runs = opts[:runs] || 3

    Mix.shell().info(
      "strategy x scenario: makespan/ideal, idle %, messages and bytes per atom " <>
        "(#{size}x#{size}, #{k} atoms per child; #{vm()})"
    )

    real = [
      {"4 equal", "priv/scenes/balls_s2.nff", children: 4, speeds: []},
      {"4, one 4x slower", "priv/scenes/balls_s2.nff", children: 4, speeds: [1, 1, 4, 1]},
      {"8, speeds 1..8", "priv/scenes/balls_s2.nff", children: 8, speeds: Enum.to_list(1..8)},
      {"tetra, 4 equal", "priv/scenes/spd/tetra_s6.nff", children: 4, speeds: []},
      {"teapot, 4 equal", "priv/scenes/spd/teapot_s12.nff", children: 4, speeds: []}
    ]

    # Per scenario: every strategy on the paper's strips, the ring once more
    # with offers to the left sibling only (`aim: false`) and once on
    # interleaved strips (`layout: :interleaved`), then the floor: the same
    # atoms and speeds with no protocol at all, N plain processes calling the
    # kernel and taking the next atom from one `:atomics` counter. What is
    # left between the floor and 1.0 is this machine's cost of running dirty
    # NIFs, not load balancing. Each row: one warm-up, then the median of
    # `runs`.
    runs_of =
      Enum.map(RingTracer.Strategies.names(), &{Atom.to_string(&1), [strategy: &1]}) ++
        [
          {"ring/left", [strategy: :ring, aim: false]},
          {"ring/interleaved", [strategy: :ring, layout: :interleaved]}
        ]

    rows =
      Enum.flat_map(real, fn {label, path, job} ->
        strategies =
          for {name, how} <- runs_of do
            render = fn ->
              RingTracer.render(path, how ++ [atoms: k, width: size, height: size] ++ job)
            end

            {:ok, _} = render.()
            balance_row(label, name, median_result(runs, render))
          end

        {:ok, scene} = RingTracer.Scene.load(path)
        floor = fn -> floor_run(scene, size, job[:children], k, job[:speeds]) end
        {:ok, _} = floor.()
        f = median_result(runs, floor)

        strategies ++
          [
            %{
              scenario: label,
              strategy: "floor",
              makespan_us: f.elapsed_us,
              ideal_us: f.ideal_us,
              ratio: f.elapsed_us / f.ideal_us,
              idle_pct: nil,
              msgs: 0.0,
              bytes: nil
            }
          ]
      end)

    sim_runs =
      Enum.map(RingTracer.Strategies.names(), &{Atom.to_string(&1), [strategy: &1]}) ++
        [{"ring/left", [strategy: :ring, aim: false]}]

    sim_rows =
      for n <- sims, {name, how} <- sim_runs do
        # Speeds from 1 to 4 (a fixed pseudo-random draw) and atom costs of
        # 20 to 80 ms varying across the image, as a real scene's do.
        :rand.seed(:exsss, {n, 1, 2})
        speeds = for _ <- 1..n, do: Enum.random([1, 1, 1, 2, 2, 3, 4])

        costs =
          List.to_tuple(for a <- 0..(n * @sim_atoms - 1), do: 20_000 + rem(a * 7919, 60_000))

        result =
          median_result(if(n > 256, do: 1, else: runs), fn ->
            RingTracer.simulate(
              how ++ [children: n, atoms: @sim_atoms, speeds: speeds, costs: costs]
            )
          end)

        balance_row("simulated N=#{n}", name, result)
      end

    print_table(
      ~w(scenario strategy makespan_ms ideal_ms makespan/ideal idle% msgs/atom bytes/atom),
      Enum.map(rows ++ sim_rows, fn r ->
        [r.scenario, r.strategy, fmt(r.makespan_us / 1000), fmt(r.ideal_us / 1000)] ++
          Enum.map([r.ratio, r.idle_pct, r.msgs, r.bytes], &(&1 && fmt(&1)))
      end)
    )

    print_targets(Enum.map(real, &elem(&1, 0)), rows ++ sim_rows)
  end

  def run(["nodes" | argv]) do
    {opts, _, _} =
      OptionParser.parse(argv, strict: [scene: :string, children: :integer, runs: :integer])

    scene = opts[:scene] || "priv/scenes/spd/balls_s4.nff"
    children = opts[:children] || 6
    runs = opts[:runs] || 3
    Mix.Task.run("app.start")
    RingTracer.Cluster.Distribution.start!(generate: true)
    peers = for name <- ["bench_w1", "bench_w2"], do: RingTracer.LocalCluster.start(name)
    nodes = Enum.map(peers, &elem(&1, 1))

    Mix.shell().info(
      "#{scene}, #{children} children x 16 atoms, median of #{runs}; 3 nodes = this one and 2 peers on the same #{System.schedulers_online()} cores"
    )

    one = median_result(runs, fn -> RingTracer.render(scene, children: children) end)

    three =
      median_result(runs, fn -> RingTracer.render(scene, children: children, nodes: nodes) end)

    rows =
      for {label, r} <- [{"1 node", one}, {"3 nodes", three}] do
        bytes = r.nodes |> Enum.map_join(" ", fn {n, s} -> "#{n}:#{s.scene_bytes}" end)
        [label, fmt(r.elapsed_us / 1000), fmt(r.elapsed_us / one.elapsed_us), bytes]
      end

    print_table(~w(layout makespan_ms vs_1_node scene_bytes_per_node), rows)
    Enum.each(peers, fn {peer, _} -> RingTracer.LocalCluster.stop(peer) end)
  end

  def run(["rays" | meshes]) when meshes != [] do
    # The ray-casting benchmark is the kernel's own cargo example (no BEAM
    # in the loop): BVH build time, then Mrays/s for primary and incoherent
    # rays with 1 and 2 threads, and the hit counts.
    cargo = System.find_executable("cargo") || Path.expand("~/.cargo/bin/cargo")

    args = [
      "run",
      "--release",
      "-q",
      "-p",
      "ring_tracer_kernel",
      "--example",
      "bench",
      "--",
      "--raycast"
    ]

    {_, status} =
      System.cmd(cargo, args ++ Enum.map(meshes, &Path.expand/1),
        cd: "native",
        into: IO.stream(:stdio, :line),
        stderr_to_stdout: true
      )

    if status != 0, do: Mix.raise("the ray-casting benchmark failed (exit #{status})")
  end

  def run(_),
    do:
      Mix.raise(
        "usage: mix ring_tracer.bench kernel|balance|nodes|rays [options]  (see mix help ring_tracer.bench)"
      )

  defp median_result(runs, fun) do
    results = for _ <- 1..runs, do: elem(fun.(), 1)
    sorted = Enum.sort_by(results, &(&1.elapsed_us / max(&1.ideal_us, 1)))
    Enum.at(sorted, div(runs, 2))
  end

  # Makespan and ideal time of `n` processes tracing the image's atoms, each
  # taking the next from a shared counter, with the same slowdowns as a job.
  defp floor_run(scene, size, n, k, speeds) do
    settings = %Settings{width: size, height: size}
    context = {scene, Settings.to_native(settings)}
    layout = RingTracer.Layout.new(size, size, n, k)
    total = RingTracer.Layout.atom_count(layout)
    next = :atomics.new(1, [])
    speeds = if speeds == [], do: List.duplicate(1, n), else: speeds

    {elapsed, traces} =
      :timer.tc(fn ->
        speeds
        |> Enum.map(fn speed ->
          Task.async(fn ->
            floor_loop(next, total, context, layout, Slowdown.new(speed), [])
          end)
        end)
        |> Enum.flat_map(&Task.await(&1, :infinity))
      end)

    cap = :erlang.system_info(:dirty_cpu_schedulers_online)
    {:ok, %{elapsed_us: elapsed, ideal_us: RingTracer.Result.ideal_us(traces, speeds, cap)}}
  end

  defp floor_loop(next, total, context, layout, slowdown, acc) do
    atom = :atomics.add_get(next, 1, 1) - 1

    if atom < total do
      {first, count} = RingTracer.Layout.span(layout, atom)
      {:ok, _pixels, _rays, us} = RingTracer.Kernel.Native.trace(context, first, count, atom)
      slowdown = Slowdown.wait(slowdown, us)
      floor_loop(next, total, context, layout, slowdown, [%{trace_us: us} | acc])
    else
      acc
    end
  end

  defp balance_row(label, name, result) do
    n = length(result.children)
    idle = Enum.sum(Enum.map(result.children, & &1.idle_us)) / max(n * result.elapsed_us, 1)
    per = RingTracer.Result.per_atom(result)

    %{
      scenario: label,
      strategy: name,
      makespan_us: result.elapsed_us,
      ideal_us: result.ideal_us,
      ratio: result.elapsed_us / max(result.ideal_us, 1),
      idle_pct: idle * 100,
      msgs: per.messages,
      bytes: per.bytes
    }
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

  # The VM the figures come from: its schedulers, and the flags that decide
  # whether idle schedulers spin (`bin/ringtracer` sets them in ERL_FLAGS).
  defp vm do
    flags =
      case System.get_env("ERL_FLAGS", "") do
        "" -> "ERL_FLAGS unset"
        f -> "ERL_FLAGS #{inspect(f)}"
      end

    "#{System.schedulers_online()} schedulers, " <>
      "#{:erlang.system_info(:dirty_cpu_schedulers_online)} dirty CPU schedulers, #{flags}"
  end

  # Issue 4's targets against the table's rows: each says "ok" or "MISSED".
  defp print_targets(real, rows) do
    value = fn scenario, strategy, key ->
      Enum.find_value(rows, &(&1.scenario == scenario and &1.strategy == strategy and &1[key]))
    end

    ratio = &value.(&1, &2, :ratio)
    msgs = &value.(&1, &2, :msgs)
    verdict = fn ok -> if ok, do: "ok", else: "MISSED" end

    sims =
      rows
      |> Enum.map(& &1.scenario)
      |> Enum.filter(&String.starts_with?(&1, "simulated"))
      |> Enum.uniq()

    lines = [
      "ring <= 1.10 x ideal:" <>
        Enum.map_join(real, ";", fn s ->
          " #{s} #{fmt(ratio.(s, "ring"))} #{verdict.(ratio.(s, "ring") <= 1.10)}"
        end),
      "(not a target) the ring with offers to the left only <= 1.10 x ideal:" <>
        Enum.map_join(real, ";", fn s ->
          r = ratio.(s, "ring/left")
          " #{s} #{fmt(r)} #{if r <= 1.10, do: "yes", else: "no"}"
        end),
      "(not a target) the ring on interleaved strips <= 1.10 x ideal:" <>
        Enum.map_join(real, ";", fn s ->
          r = ratio.(s, "ring/interleaved")
          " #{s} #{fmt(r)} #{if r <= 1.10, do: "yes", else: "no"}"
        end),
      "ring <= 1.15 x ideal at N=1024:" <>
        if("simulated N=1024" in sims,
          do:
            " #{fmt(ratio.("simulated N=1024", "ring"))} " <>
              verdict.(ratio.("simulated N=1024", "ring") <= 1.15),
          else: " not run (--quick)"
        ),
      "static worse than ring (speeds or strips differ):" <>
        Enum.map_join(real -- ["4 equal"], ";", fn s ->
          " #{s} #{fmt(ratio.(s, "static"))} vs #{fmt(ratio.(s, "ring"))} " <>
            verdict.(ratio.(s, "static") > ratio.(s, "ring"))
        end),
      "ring fewer messages per atom than master:" <>
        Enum.map_join(real ++ sims, ";", fn s ->
          " #{s} #{fmt(msgs.(s, "ring"))} vs #{fmt(msgs.(s, "master"))} " <>
            verdict.(msgs.(s, "ring") < msgs.(s, "master"))
        end)
    ]

    Mix.shell().info("\ntargets (issue 4):\n" <> Enum.map_join(lines, "\n", &("  " <> &1)))
  end

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
