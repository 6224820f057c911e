defmodule RingTracer.Bench.Network do
  @help """
  The network benchmark: every strategy rendering over rate-limited,
  delayed links between nodes in Linux network namespaces
  (`RingTracer.Bench.Network.Lab`; needs root).

      mix ring_tracer.bench network [--delays 0,1,10,50] [--rate 1gbit] [--workers 2]
        [--children 2] [--atoms 16] [--size 512] [--speeds 1,1,4,1] [--runs 3]
        [--scene priv/scenes/spd/rings_s7.nff] [--strategies static,master,ring,steal]

  The parent runs on a node of its own (it hosts no children); the
  children are on `--workers` worker nodes, `--children` on each, with
  `--speeds` (one slowdown factor per child, in ring order). Each link is
  limited to `--rate` both ways (`tc tbf`) and the relay holds every byte
  for the one-way delay. For each delay it prints the measured round trip
  (parent to workers, `:net_adm.ping/1`) and the makespan of an empty job
  (8x8 pixels, one atom per child: the job's fixed cost), then per
  strategy the median (by makespan / ideal) of `--runs` renders after one
  warm-up:

    * `makespan/ideal` — the ideal being the total trace work over the
      atoms that can trace at once (one per worker node's dirty scheduler,
      at most the sum of the children's capacities);
    * `msgs/atom`, `bytes/atom` — distribution packets and their bytes,
      sent by all nodes (`:inet.getstat/2` on the distribution sockets),
      per atom: what actually crossed between nodes, pixels included;
    * `wire/atom` — bytes the nodes put on their links, TCP/IP headers and
      acknowledgements included (the veths' counters);
    * `parent_bytes%`, `parent_msgs%` — the share of that traffic that the
      parent sent or received;
    * `parent_link_ms` — the time the parent's link needs, at `--rate`, for
      the bytes that came in to the parent during the run (every pixel
      among them): a floor under the makespan that no strategy can go
      below, since all pixels end at the parent. Near the makespan, the
      parent's link is the bottleneck.

  Every image is compared with a render on this VM alone; the last line
  says whether all were byte-identical.
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "network [--delays 0,1,10,50] [--rate 1gbit] [--workers 2] [--runs 3] ..."

  alias RingTracer.Bench.Network.{Lab, Remote}

  @defaults [
    delays: "0,1,10,50",
    rate: "1gbit",
    workers: 2,
    children: 2,
    atoms: 16,
    size: 512,
    speeds: "1,1,4,1",
    runs: 3,
    scene: "priv/scenes/spd/rings_s7.nff",
    strategies: "static,master,ring,steal"
  ]

  @switches [
    delays: :string,
    rate: :string,
    workers: :integer,
    children: :integer,
    atoms: :integer,
    size: :integer,
    speeds: :string,
    runs: :integer,
    scene: :string,
    strategies: :string
  ]

  @doc "Runs the benchmark with command-line `args` and prints its table."
  @impl RingTracer.Bench
  @spec run([String.t()]) :: :ok
  def run(args) do
    Mix.Task.run("app.start")
    {opts, _, invalid} = OptionParser.parse(args, strict: @switches)
    if invalid != [], do: raise(ArgumentError, "unknown options: #{inspect(invalid)}")
    opts = Keyword.merge(@defaults, opts)

    case Lab.probe() do
      :ok ->
        :ok

      {:error, why} ->
        raise "the network benchmark needs network namespaces (run as root): #{why}"
    end

    {:ok, _} = Application.ensure_all_started(:ring_tracer)
    delays = numbers(opts[:delays])
    strategies = opts[:strategies] |> String.split(",") |> Enum.map(&strategy/1)
    job = job(opts)
    scene = Path.expand(opts[:scene])

    {:ok, local} = RingTracer.render(scene, Keyword.drop(job, [:speeds]))
    reference = :crypto.hash(:sha256, local.pixels)

    IO.puts(
      "#{opts[:scene]} #{opts[:size]}x#{opts[:size]}: parent on its own node, " <>
        "#{opts[:workers]} worker nodes x #{opts[:children]} children x #{opts[:atoms]} atoms, " <>
        "speeds #{opts[:speeds]}; links #{opts[:rate]} (tbf) each way, one-way delay in a relay; " <>
        "median of #{opts[:runs]} after a warm-up; #{System.schedulers_online()} cores"
    )

    {rows, identical} =
      Lab.with_lab([workers: opts[:workers], rate: opts[:rate]], fn lab ->
        for delay <- delays, reduce: {[], true} do
          {rows, same} ->
            :ok = Lab.set_delay(lab, delay)
            rtt = lab |> Lab.rtt_ms() |> Map.values()
            empty = empty_job_ms(lab, scene, opts)

            IO.puts(
              "one-way delay #{fmt(delay)} ms: round trip parent -> each worker, median of 7 pings: " <>
                Enum.map_join(rtt, ", ", &"#{fmt(&1)} ms") <>
                "; an empty job (8x8 pixels, 1 atom per child, ring): #{fmt(empty)} ms"
            )

            for strategy <- strategies, reduce: {rows, same} do
              {rows, same} ->
                row = measure(lab, scene, [strategy: strategy] ++ job, opts)
                ok = Enum.all?(row.shas, &(&1 == reference))

                {rows ++ [Map.merge(row, %{delay: delay, rtt: median(rtt), strategy: strategy})],
                 same and ok}
            end
        end
      end)

    print_table(rows, Lab.rate_bps(opts[:rate]))

    IO.puts(
      "every image byte-identical to the local render: #{if identical, do: "yes", else: "NO"}"
    )
  end

  @doc false
  # The render options of a job with its children on the workers.
  @spec job(keyword()) :: keyword()
  def job(opts) do
    speeds = numbers(opts[:speeds])
    children = opts[:workers] * opts[:children]
    speeds = if speeds == [], do: [], else: Enum.take(Stream.cycle(speeds), children)

    [
      atoms: opts[:atoms],
      width: opts[:size],
      height: opts[:size],
      children: children,
      speeds: Enum.map(speeds, &round/1)
    ]
  end

  @doc """
  One row: a warm-up, then `opts[:runs]` renders on the lab's parent with
  the children on its workers, each between two readings of every node's
  counters. Returns the median run's figures and every run's image hash.
  """
  @spec measure(Lab.t(), Path.t(), keyword(), keyword()) :: map()
  def measure(lab, scene, job, opts) do
    cap = min(length(lab.workers), System.schedulers_online())

    render_opts =
      Keyword.merge(job,
        nodes: lab.workers,
        local: false,
        children_per_node: opts[:children]
      )
      |> Keyword.delete(:children)

    {:ok, _} = Lab.call(lab.parent, Remote, :render, [scene, render_opts, cap, false])

    samples =
      for _ <- 1..opts[:runs] do
        before = Lab.counters(lab)
        {:ok, r} = Lab.call(lab.parent, Remote, :render, [scene, render_opts, cap, false])
        after_ = Lab.counters(lab)
        figures(lab, r, before, after_)
      end

    sorted = Enum.sort_by(samples, & &1.ratio)
    Map.put(Enum.at(sorted, div(length(sorted), 2)), :shas, Enum.map(samples, & &1.sha))
  end

  # The job's fixed cost at this delay: start-up, scene hand-out, the end
  # of the job, with (almost) no work. The median of three after a warm-up.
  defp empty_job_ms(lab, scene, opts) do
    job = [
      strategy: :ring,
      nodes: lab.workers,
      local: false,
      children_per_node: opts[:children],
      atoms: 1,
      width: 8,
      height: 8
    ]

    samples =
      for _ <- 0..3 do
        {:ok, r} = Lab.call(lab.parent, Remote, :render, [scene, job, 1, false])
        r.elapsed_us / 1000
      end

    median(tl(samples))
  end

  defp figures(lab, r, before, after_) do
    delta =
      Map.new(after_, fn {n, c} ->
        {n, Map.new(c, fn {k, v} -> {k, v - before[n][k]} end)}
      end)

    p = delta[lab.parent.name]
    sum = fn key -> delta |> Map.values() |> Enum.map(& &1[key]) |> Enum.sum() end
    sent_bytes = sum.(:send_oct)
    sent_msgs = sum.(:send_cnt)

    %{
      elapsed_us: r.elapsed_us,
      ideal_us: r.ideal_us,
      ratio: r.elapsed_us / max(r.ideal_us, 1),
      atoms: r.atoms,
      msgs: sent_msgs / r.atoms,
      bytes: sent_bytes / r.atoms,
      wire: sum.(:link_rx) / r.atoms,
      parent_bytes: share(p.send_oct + p.recv_oct, sent_bytes),
      parent_msgs: share(p.send_cnt + p.recv_cnt, sent_msgs),
      parent_in: p.link_tx,
      sha: r.sha
    }
  end

  defp share(_, 0), do: 0.0
  defp share(part, total), do: 100 * part / total

  defp print_table(rows, rate_bps) do
    header =
      ~w(delay_ms rtt_ms strategy makespan_ms ideal_ms makespan/ideal msgs/atom bytes/atom wire/atom parent_bytes% parent_msgs% parent_link_ms)

    cells =
      for r <- rows do
        link_ms = r.parent_in * 8 * 1000 / rate_bps

        [fmt(r.delay), fmt(r.rtt), Atom.to_string(r.strategy), fmt(r.elapsed_us / 1000)] ++
          [fmt(r.ideal_us / 1000), fmt(r.ratio), fmt(r.msgs), int(r.bytes), int(r.wire)] ++
          [fmt1(r.parent_bytes), fmt1(r.parent_msgs), fmt(link_ms)]
      end

    widths =
      Enum.map(Enum.zip([header | cells]), fn col ->
        col |> Tuple.to_list() |> Enum.map(&String.length/1) |> Enum.max()
      end)

    for row <- [header | cells] do
      row
      |> Enum.zip(widths)
      |> Enum.map_join("  ", fn {cell, w} -> String.pad_leading(cell, w) end)
      |> IO.puts()
    end
  end

  defp strategy(name) do
    Enum.find(RingTracer.Strategies.names(), &(Atom.to_string(&1) == name)) ||
      raise ArgumentError,
            "--strategies: one of #{Enum.join(RingTracer.Strategies.names(), ", ")}, got: #{inspect(name)}"
  end

  defp numbers(text) do
    text
    |> String.split(",", trim: true)
    |> Enum.map(fn s ->
      case Float.parse(String.trim(s)) do
        {x, ""} -> if x == trunc(x), do: trunc(x), else: x
        _ -> raise ArgumentError, "a list of numbers such as 0,1,10,50, got: #{inspect(text)}"
      end
    end)
  end

  defp median(list), do: Enum.at(Enum.sort(list), div(length(list), 2))
  defp fmt(x), do: :erlang.float_to_binary(x / 1, decimals: 3)
  defp fmt1(x), do: :erlang.float_to_binary(x / 1, decimals: 1)
  defp int(x), do: Integer.to_string(round(x))
end
