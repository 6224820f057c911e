defmodule RingTracer.Bench.Balance do
  @help """
  Strategy x scenario: makespan / ideal and messages per atom.

      mix ring_tracer.bench balance [--size 1024] [--atoms 16] [--runs 3] [--quick]

  Renders the same atoms with every strategy (`static`, `master`, `ring`,
  `steal`) on real scenes (4 equal children; 4 with one 4x slower; 8 with
  speeds 1..8; SPD tetra and teapot, whose empty background makes static
  strips unequal) and on the simulated kernel with 64, 256 and 1024
  children, and prints makespan / ideal, idle %, and messages and bytes per
  atom (counted at the sender; bytes include the pixels). Each real row is
  the median (by makespan / ideal) of `--runs` renders after one warm-up.
  Each real scenario also runs the ring on interleaved strips
  (`ring/interleaved`, `layout: :interleaved`: child i owns atoms i, i + N,
  ...; see `RingTracer.Layout`), which shows how much of the ring's loss
  comes with the paper's contiguous strips, and every scenario runs it
  once more on strips with every offer sent to the left sibling as in the
  paper (`ring/left`, `aim: false`; see `RingTracer.Strategy.Ring.Aim`), and with
  atoms cut in pieces near the end (`ring/split`, `split: true`: adaptive atoms, see
  `RingTracer.Strategy.Ring`). For each real
  scenario a `floor` row runs the same atoms and speeds with no protocol at
  all (`floor/5`: N grandchildren fed from one shared counter): the
  distance from it to 1.0 is this machine's cost of dirty NIF calls, not
  load balancing. Images are 1024x1024 by default: at 512x512 the real jobs
  last 20 to 170 ms, and one atom or one scheduling hiccup is then several
  percent of the makespan even for the `floor`. Under the table it checks
  the targets of `RingTracer.Bench.Targets` against it, each "ok" or
  "MISSED".
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.{Layout, Result, Settings}
  alias RingTracer.Bench.Targets
  alias RingTracer.Job.{Grandchild, Pipe}

  @sim_atoms 64

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "balance [--size 1024] [--atoms 16] [--runs 3] [--quick]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [size: :integer, atoms: :integer, quick: :boolean, runs: :integer]
      )

    Mix.Task.run("app.start")
    size = opts[:size] || 1024
    k = opts[:atoms] || 16
    sims = if opts[:quick], do: [64], else: [64, 256, 1024]
    runs = opts[:runs] || 3

    info(
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
    # atoms and speeds with no protocol at all. Each row: one warm-up, then
    # the median of `runs`.
    runs_of =
      Enum.map(RingTracer.Strategies.names(), &{Atom.to_string(&1), [strategy: &1]}) ++
        [
          {"ring/split", [strategy: :ring, split: true]},
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
            row(label, name, median_result(runs, render))
          end

        {:ok, scene} = RingTracer.Scene.load(path)
        floor = fn -> floor(scene, size, job[:children], k, job[:speeds]) end
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
        [
          {"ring/split", [strategy: :ring, split: true]},
          {"ring/left", [strategy: :ring, aim: false]}
        ]

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

        row("simulated N=#{n}", name, result)
      end

    print_table(
      ~w(scenario strategy makespan_ms ideal_ms makespan/ideal idle% msgs/atom bytes/atom),
      Enum.map(rows ++ sim_rows, &cells/1)
    )

    info(Targets.report(Enum.map(real, &elem(&1, 0)), rows ++ sim_rows))
  end

  @doc """
  The floor of a job: `n` real grandchildren (`RingTracer.Job.Grandchild`,
  the same code a child feeds, with the same slowdowns) tracing the image's
  `n` x `k` atoms of `scene` at `size` x `size`, each fed the next atom from
  one shared counter as soon as it sends back the last. No strategy, no
  parent: what remains between its makespan and the ideal time is the cost
  of the kernel calls themselves. Returns the makespan and the ideal time,
  as `RingTracer.Result` has them.
  """
  @spec floor(RingTracer.Scene.t(), pos_integer(), pos_integer(), pos_integer(), [number()]) ::
          {:ok, %{elapsed_us: non_neg_integer(), ideal_us: non_neg_integer()}}
  def floor(scene, size, n, k, speeds) do
    settings = %Settings{width: size, height: size}
    kernel = {RingTracer.Kernel.Native, {scene, Settings.to_native(settings)}}
    layout = Layout.new(size, size, n, k)
    total = Layout.atom_count(layout)
    next = :atomics.new(1, [])
    speeds = if speeds == [], do: List.duplicate(1, n), else: speeds

    {elapsed, traces} =
      :timer.tc(fn ->
        speeds
        |> Enum.map(fn speed ->
          Task.async(fn -> feeder(kernel, layout, speed, next, total) end)
        end)
        |> Enum.flat_map(&Task.await(&1, :infinity))
      end)

    cap = :erlang.system_info(:dirty_cpu_schedulers_online)
    {:ok, %{elapsed_us: elapsed, ideal_us: Result.ideal_us(traces, speeds, cap)}}
  end

  defp feeder(kernel, layout, speed, next, total) do
    gc = Grandchild.start_link(kernel, layout, speed)
    traces = feed(gc, next, total, [])
    Process.unlink(gc)
    Process.exit(gc, :kill)
    Pipe.forget(gc)
    traces
  end

  defp feed(gc, next, total, acc) do
    atom = :atomics.add_get(next, 1, 1) - 1

    if atom < total do
      send(gc, {:trace, atom})

      receive do
        {:traced, ^gc, ^atom, _pixels, _rays, timing} ->
          Pipe.release(gc, atom)
          feed(gc, next, total, [%{trace_us: timing.trace_us} | acc])

        {:atom_failed, ^gc, ^atom, message} ->
          raise "the floor's atom #{atom} failed: #{message}"
      end
    else
      acc
    end
  end

  @doc """
  A row of the table from a job's result: makespan, ideal time, their
  ratio, idle % of the children's time, and messages and bytes per atom.
  """
  @spec row(String.t(), String.t(), Result.t()) :: Targets.row()
  def row(label, name, result) do
    n = length(result.children)
    idle = Enum.sum(Enum.map(result.children, & &1.idle_us)) / max(n * result.elapsed_us, 1)
    per = Result.per_atom(result)

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

  @doc """
  A row's cells as printed.

      iex> RingTracer.Bench.Balance.cells(%{scenario: "4 equal", strategy: "floor",
      ...>   makespan_us: 213_104, ideal_us: 209_712, ratio: 1.016, idle_pct: nil, msgs: 0.0, bytes: nil})
      ["4 equal", "floor", "213.104", "209.712", "1.016", nil, "0.000", nil]
  """
  @spec cells(Targets.row()) :: [String.t() | nil]
  def cells(r) do
    [r.scenario, r.strategy, fmt(r.makespan_us / 1000), fmt(r.ideal_us / 1000)] ++
      Enum.map([r.ratio, r.idle_pct, r.msgs, r.bytes], &(&1 && fmt(&1)))
  end
end
