defmodule RingTracer.Bench.Balance do
  @help """
  Strategy x scenario: makespan / ideal and messages per atom.

      mix ring_tracer.bench balance [--size 1024] [--atoms 16] [--runs 3] [--quick] [--why]

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
  paper (`ring/left`, `strategy: {:ring, aim: false}`; see `RingTracer.Strategy.Ring.Aim`), and with
  atoms cut in pieces near the end (`ring/split`, `strategy: {:ring, split: true}`: adaptive atoms, see
  `RingTracer.Strategy.Ring`). For each real
  scenario a `floor` row runs the same atoms and speeds with no protocol at
  all (`floor/5`: N grandchildren fed from one shared counter): the
  distance from it to 1.0 is this machine's cost of dirty NIF calls, not
  load balancing. Images are 1024x1024 by default: at 512x512 the real jobs
  last 20 to 170 ms, and one atom or one scheduling hiccup is then several
  percent of the makespan even for the `floor`. Under the table it checks
  the targets of `RingTracer.Bench.Targets` against it, each "ok" or
  "MISSED".

  `--why` prints a second table: where each row's makespan goes at the end
  of the job (`tail/1`), for the floor too (`floor/5` keeps its feeders'
  last atoms).
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.{Layout, Result, Settings}
  alias RingTracer.Bench.Targets
  alias RingTracer.Job.{Grandchild, Pipe}

  @sim_atoms 64

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "balance [--size 1024] [--atoms 16] [--runs 3] [--quick] [--why]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [
          size: :integer,
          atoms: :integer,
          quick: :boolean,
          runs: :integer,
          why: :boolean
        ]
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
    # with offers to the left sibling only (`{:ring, aim: false}`) and once on
    # interleaved strips (`layout: :interleaved`), then the floor: the same
    # atoms and speeds with no protocol at all. Each row: one warm-up, then
    # the median of `runs`.
    runs_of =
      Enum.map(RingTracer.Strategies.names(), &{Atom.to_string(&1), [strategy: &1]}) ++
        [
          {"ring/split", [strategy: {:ring, split: true}]},
          {"ring/left", [strategy: {:ring, aim: false}]},
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
              bytes: nil,
              tail: f.tail
            }
          ]
      end)

    sim_runs =
      Enum.map(RingTracer.Strategies.names(), &{Atom.to_string(&1), [strategy: &1]}) ++
        [
          {"ring/split", [strategy: {:ring, split: true}]},
          {"ring/left", [strategy: {:ring, aim: false}]}
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

    if opts[:why] do
      info("\nwhere the makespan goes at the end of the job (`tail/1`; times in ms):")

      print_table(
        ~w(scenario strategy makespan_ms first_idle_ms tail_ms last_ms last_speed gives_late offer_ms),
        Enum.map(rows ++ sim_rows, &tail_cells/1)
      )
    end
  end

  @doc """
  Where a job's makespan goes at its end, from its result (or the floor's):

    * `:first_idle_us` — from the first child to trace its last atom to the
      end: how long capacity lay unused at all;
    * `:tail_us` — from the median child's last atom to the end: how long
      half the children had nothing left;
    * `:last_us` and `:last_speed` — how long the atom or piece that ended
      last took (its slowdown included) and its child's speed factor: a big
      atom started late on a slow child sets the makespan;
    * `:gives_late` — hand-overs (`:give` events) in the last tenth of the
      makespan, and `:offer_us`, the median time from an offer to the
      hand-over it brought (nil without hand-overs).

      iex> RingTracer.Bench.Balance.tail(%{elapsed_us: 100,
      ...>   atoms: [%{child: 0, start_us: 0, end_us: 60}, %{child: 1, start_us: 10, end_us: 99}],
      ...>   children: [%{index: 0, speed: 1, last_atom_us: 60}, %{index: 1, speed: 4, last_atom_us: 99}],
      ...>   events: [%{kind: :offer, from: 0, to: 1, at_us: 60}, %{kind: :give, from: 1, to: 0, at_us: 95}]})
      %{first_idle_us: 40, tail_us: 1, last_us: 89, last_speed: 4, gives_late: 1, offer_us: 35}
  """
  @spec tail(%{
          required(:elapsed_us) => non_neg_integer(),
          required(:atoms) => [map()],
          required(:children) => [map()],
          required(:events) => [map()],
          optional(atom()) => term()
        }) :: map()
  def tail(%{elapsed_us: elapsed, atoms: atoms, children: children, events: events}) do
    ends = children |> Enum.map(& &1.last_atom_us) |> Enum.reject(&is_nil/1) |> Enum.sort()
    last = Enum.max_by(atoms, & &1.end_us, fn -> nil end)
    speed = last && Enum.find_value(children, &(&1.index == last.child && &1.speed))

    %{
      first_idle_us: if(ends == [], do: 0, else: elapsed - hd(ends)),
      tail_us: if(ends == [], do: 0, else: elapsed - Enum.at(ends, div(length(ends), 2))),
      last_us: last && last.end_us - last.start_us,
      last_speed: speed,
      gives_late: Enum.count(events, &(&1.kind == :give and &1.at_us > elapsed * 0.9)),
      offer_us: offer_us(events)
    }
  end

  # For each hand-over, the time since its receiver's latest offer.
  defp offer_us(events) do
    {waits, _} =
      Enum.reduce(events, {[], %{}}, fn
        %{kind: :offer, from: from, at_us: t}, {waits, sent} ->
          {waits, Map.put(sent, from, t)}

        %{kind: :give, to: to, at_us: t}, {waits, sent} when is_map_key(sent, to) ->
          {[t - sent[to] | waits], Map.delete(sent, to)}

        _, acc ->
          acc
      end)

    if waits != [], do: waits |> Enum.sort() |> Enum.at(div(length(waits), 2))
  end

  defp tail_cells(%{tail: t} = r) do
    ms = &(&1 && fmt(&1 / 1000))

    [r.scenario, r.strategy, fmt(r.makespan_us / 1000)] ++
      [ms.(t.first_idle_us), ms.(t.tail_us), ms.(t.last_us)] ++
      [t.last_speed && to_string(t.last_speed), to_string(t.gives_late), ms.(t.offer_us)]
  end

  @doc """
  The floor of a job: `n` real grandchildren (`RingTracer.Job.Grandchild`,
  the same code a child feeds, with the same slowdowns) tracing the image's
  `n` x `k` atoms of `scene` at `size` x `size`, each fed the next atom from
  one shared counter as soon as it sends back the last. No strategy, no
  parent: what remains between its makespan and the ideal time is the cost
  of the kernel calls themselves. Returns the makespan and the ideal time,
  as `RingTracer.Result` has them, and the `tail/1` of its feeders.
  """
  @spec floor(RingTracer.Scene.t(), pos_integer(), pos_integer(), pos_integer(), [number()]) ::
          {:ok, %{elapsed_us: non_neg_integer(), ideal_us: non_neg_integer(), tail: map()}}
  def floor(scene, size, n, k, speeds) do
    settings = %Settings{width: size, height: size}
    kernel = {RingTracer.Kernel.Native, {scene, Settings.to_native(settings)}}
    floor_of(kernel, Layout.new(size, size, n, k), speeds)
  end

  @doc """
  The floor of `layout`'s atoms (of every frame) traced by `kernel`
  (`{module, context}`) on grandchildren of `speeds`, as `floor/5`.
  """
  @spec floor_of({module(), term()}, Layout.t(), [number()]) ::
          {:ok, %{elapsed_us: non_neg_integer(), ideal_us: non_neg_integer(), tail: map()}}
  def floor_of(kernel, layout, speeds) do
    n = layout.children
    total = Layout.atom_count(layout)
    next = :atomics.new(1, [])
    speeds = if speeds == [], do: List.duplicate(1, n), else: speeds

    t0 = System.monotonic_time(:microsecond)

    {elapsed, per_feeder} =
      :timer.tc(fn ->
        speeds
        |> Enum.map(fn speed ->
          Task.async(fn -> feeder(kernel, layout, speed, next, total, t0) end)
        end)
        |> Enum.map(&Task.await(&1, :infinity))
      end)

    traces = Enum.concat(per_feeder)
    cap = :erlang.system_info(:dirty_cpu_schedulers_online)

    children =
      per_feeder
      |> Enum.zip(speeds)
      |> Enum.with_index(fn {traces, speed}, i ->
        %{
          index: i,
          speed: speed,
          last_atom_us: Enum.max(Enum.map(traces, & &1.end_us), fn -> nil end)
        }
      end)

    atoms =
      per_feeder
      |> Enum.with_index()
      |> Enum.flat_map(fn {traces, i} -> Enum.map(traces, &Map.put(&1, :child, i)) end)

    tail = tail(%{elapsed_us: elapsed, atoms: atoms, children: children, events: []})
    {:ok, %{elapsed_us: elapsed, ideal_us: Result.ideal_us(traces, speeds, cap), tail: tail}}
  end

  defp feeder(kernel, layout, speed, next, total, t0) do
    gc = Grandchild.start_link(kernel, layout, speed)
    traces = feed(gc, next, total, t0, [])
    Process.unlink(gc)
    Process.exit(gc, :kill)
    Pipe.forget(gc)
    traces
  end

  defp feed(gc, next, total, t0, acc) do
    atom = :atomics.add_get(next, 1, 1) - 1

    if atom < total do
      start = System.monotonic_time(:microsecond) - t0
      send(gc, {:trace, atom})

      receive do
        {:traced, ^gc, ^atom, _pixels, _rays, timing} ->
          Pipe.release(gc, atom)
          done = System.monotonic_time(:microsecond) - t0
          trace = %{trace_us: timing.trace_us, start_us: start, end_us: done}
          feed(gc, next, total, t0, [trace | acc])

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
      bytes: per.bytes,
      tail: tail(result)
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
