defmodule RingTracer.Bench.Network do
  @help """
  The network benchmark: every strategy rendering over rate-limited,
  delayed links between nodes in Linux network namespaces
  (`RingTracer.Bench.Network.Lab`; needs root).

      mix ring_tracer.bench network [--delays 0,1,10,50] [--rates 1gbit,100mbit]
        [--workers 2] [--children 2] [--atoms 16] [--size 512] [--speeds 1,1,4,1]
        [--runs 3] [--pixels srgb8] [--scene priv/scenes/spd/rings_s7.nff]
        [--strategies static,master,ring,steal]

  The parent runs on a node of its own (it hosts no children); the
  children are on `--workers` worker nodes, `--children` on each, with
  `--speeds` (one slowdown factor per child, in ring order). The job's
  pixels travel as `--pixels` (`srgb8`, a PNG job's, or `float`, an EXR
  job's). Each link is limited to each of `--rates` in turn, both ways
  (`tc tbf`), and the relay holds every byte for the one-way delay. For
  each rate and delay it prints the measured round trip (parent to
  workers, `:net_adm.ping/1`) and the time of an empty job (8x8 pixels,
  one atom per child: the job's fixed cost) to its last atom and until
  the render's call returned, in round trips; then per strategy the
  median (by makespan / ideal) of `--runs` renders after one warm-up:

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
    * `parent_in/px` — the bytes that came in on the parent's link during
      the run (TCP/IP headers included) per pixel of the image;
    * `parent_link_ms` — the time the parent's link needs, at the rate, for
      those bytes (every pixel among them): a floor under the makespan
      that no strategy can go below, since all pixels end at the parent.
      Near the makespan, the parent's link is the bottleneck.

  Every image is compared with a render on this VM alone. The last lines
  hold the figures against their targets: bytes per pixel into the
  parent, the ring's makespan at the lowest rate over the highest, the
  empty job against three round trips plus 10 ms, and whether every image
  was byte-identical.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "network [--delays 0,1,10,50] [--rates 1gbit,100mbit] [--runs 3] ..."

  alias RingTracer.Bench.Network.{Lab, Remote}

  @defaults [
    delays: "0,1,10,50",
    rates: "1gbit,100mbit",
    pixels: "srgb8",
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
    rates: :string,
    rate: :string,
    pixels: :string,
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
    rates = String.split(opts[:rate] || opts[:rates], ",", trim: true)
    strategies = opts[:strategies] |> String.split(",") |> Enum.map(&strategy/1)
    job = job(opts)
    scene = Path.expand(opts[:scene])

    {:ok, local} = RingTracer.render(scene, Keyword.drop(job, [:speeds]))
    reference = :crypto.hash(:sha256, local.pixels)

    IO.puts(
      "#{opts[:scene]} #{opts[:size]}x#{opts[:size]}, #{opts[:pixels]} pixels: parent on its own node, " <>
        "#{opts[:workers]} worker nodes x #{opts[:children]} children x #{opts[:atoms]} atoms, " <>
        "speeds #{opts[:speeds]}; links #{Enum.join(rates, ", then ")} (tbf) each way, " <>
        "one-way delay in a relay; median of #{opts[:runs]} after a warm-up; " <>
        "#{System.schedulers_online()} cores"
    )

    {rows, empties, identical} =
      Lab.with_lab([workers: opts[:workers], rate: hd(rates)], fn lab ->
        for delay <- delays, reduce: {[], [], true} do
          {rows, empties, same} ->
            :ok = Lab.set_delay(lab, delay)

            empties =
              for rate <- rates, reduce: empties do
                acc ->
                  lab = Lab.set_rate(lab, rate)
                  rtt = lab |> Lab.rtt_ms() |> Map.values()
                  empty = empty_job(lab, scene, opts)
                  empty = Map.merge(empty, %{rate: rate, delay: delay, rtt: Enum.max(rtt)})
                  print_empty(rate, delay, rtt, empty)
                  acc ++ [empty]
              end

            rtt = empties |> List.last() |> Map.fetch!(:rtt)

            for strategy <- strategies, reduce: {rows, empties, same} do
              {rows, empties, same} ->
                by_rate = measure(lab, scene, [strategy: strategy] ++ job, rates, opts)

                new =
                  for rate <- rates do
                    row = Map.fetch!(by_rate, rate)
                    at = %{rate: rate, delay: delay, rtt: rtt, strategy: strategy}
                    Map.merge(row, at)
                  end

                ok = Enum.all?(new, fn row -> Enum.all?(row.shas, &(&1 == reference)) end)
                {rows ++ new, empties, same and ok}
            end
        end
      end)

    print_table(rows, opts[:size] * opts[:size])
    print_targets(rows, empties, rates, identical)
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
      speeds: Enum.map(speeds, &round/1),
      pixels: pixels(opts[:pixels])
    ]
  end

  defp pixels("srgb8"), do: :srgb8
  defp pixels("float"), do: :float

  defp pixels(other),
    do: raise(ArgumentError, "--pixels: srgb8 or float, got: #{inspect(other)}")

  @doc """
  One row per rate: a warm-up at each rate, then `opts[:runs]` rounds, each
  a render at every rate in turn (the link's rate changed between them, so
  that other load on the machine weighs on every rate alike), each render
  between two readings of every node's counters. Returns, by rate, the
  median run's figures (by makespan / ideal) and every run's image hash.
  """
  @spec measure(Lab.t(), Path.t(), keyword(), [String.t()], keyword()) :: %{String.t() => map()}
  def measure(lab, scene, job, rates, opts) do
    cap = min(length(lab.workers), System.schedulers_online())

    render_opts =
      Keyword.merge(job,
        nodes: lab.workers,
        local: false,
        children_per_node: opts[:children]
      )
      |> Keyword.delete(:children)

    render = fn -> Lab.call(lab.parent, Remote, :render, [scene, render_opts, cap, false]) end

    for rate <- rates do
      Lab.set_rate(lab, rate)
      {:ok, _} = render.()
    end

    samples =
      for round <- 1..opts[:runs], rate <- rates do
        Lab.set_rate(lab, rate)
        before = Lab.counters(lab)
        {:ok, r} = render.()
        after_ = Lab.counters(lab)
        {rate, round, figures(lab, r, before, after_)}
      end

    # Each round's makespans by rate, for ratios between rates taken within
    # one round.
    rounds =
      samples
      |> Enum.group_by(&elem(&1, 1), fn {rate, _, f} -> {rate, f.elapsed_us} end)
      |> Enum.sort()
      |> Enum.map(fn {_, pairs} -> Map.new(pairs) end)

    samples
    |> Enum.group_by(&elem(&1, 0), &elem(&1, 2))
    |> Map.new(fn {rate, runs} ->
      sorted = Enum.sort_by(runs, & &1.ratio)
      row = Enum.at(sorted, div(length(sorted), 2))
      {rate, Map.merge(row, %{shas: Enum.map(runs, & &1.sha), rounds: rounds})}
    end)
  end

  # The job's fixed cost at this delay: start-up, scene hand-out, the end
  # of the job, with (almost) no work: to its last atom (the makespan) and
  # until the render's call returned (`wall`). The median of three after a
  # warm-up.
  defp empty_job(lab, scene, opts) do
    job = [
      strategy: :ring,
      nodes: lab.workers,
      local: false,
      children_per_node: opts[:children],
      atoms: 1,
      width: 8,
      height: 8,
      pixels: pixels(opts[:pixels])
    ]

    samples =
      for _ <- 0..3 do
        {:ok, r} = Lab.call(lab.parent, Remote, :render, [scene, job, 1, false])
        %{last_atom: r.elapsed_us / 1000, wall: r.wall_us / 1000}
      end

    samples |> tl() |> Enum.sort_by(& &1.wall) |> Enum.at(1)
  end

  defp print_empty(rate, delay, rtt, empty) do
    IO.puts(
      "#{rate}, one-way delay #{fmt(delay)} ms: round trip parent -> each worker, median of 7 pings: " <>
        Enum.map_join(rtt, ", ", &"#{fmt(&1)} ms") <>
        "; an empty job (8x8 pixels, 1 atom per child, ring): last atom at " <>
        "#{fmt(empty.last_atom)} ms, returned at #{fmt(empty.wall)} ms " <>
        "(#{fmt(round_trips(empty))} round trips + 10 ms)"
    )
  end

  # The empty job's time, less 10 ms, in round trips (the slower worker's).
  defp round_trips(empty), do: max(empty.wall - 10, 0) / max(empty.rtt, 0.001)

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
      parent_in_px: p.link_tx / r.pixel_count,
      sha: r.sha
    }
  end

  defp share(_, 0), do: 0.0
  defp share(part, total), do: 100 * part / total

  defp print_table(rows, pixels) do
    header =
      ~w(rate delay_ms rtt_ms strategy makespan_ms ideal_ms makespan/ideal msgs/atom bytes/atom wire/atom parent_bytes% parent_msgs% parent_in/px parent_link_ms)

    cells =
      for r <- rows do
        link_ms = r.parent_in * 8 * 1000 / Lab.rate_bps(r.rate)

        [r.rate, fmt(r.delay), fmt(r.rtt), Atom.to_string(r.strategy)] ++
          [fmt(r.elapsed_us / 1000), fmt(r.ideal_us / 1000), fmt(r.ratio), fmt(r.msgs)] ++
          [int(r.bytes), int(r.wire), fmt1(r.parent_bytes), fmt1(r.parent_msgs)] ++
          [fmt(r.parent_in / pixels), fmt(link_ms)]
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

    :ok
  end

  # The figures against issue 44's targets, from this run's rows.
  defp print_targets(rows, empties, rates, identical) do
    pixels = rows |> Enum.map(& &1.parent_in_px) |> Enum.max(fn -> 0.0 end)
    IO.puts("targets:")
    verdict = fn ok -> if ok, do: "met", else: "NOT met" end

    IO.puts(
      "  bytes per pixel into the parent (its link, all rows): at most #{fmt(pixels)} " <>
        "(target 3.5): #{verdict.(pixels <= 3.5)}"
    )

    case {rates, Enum.filter(rows, &(&1.strategy == :ring))} do
      {[_, _ | _], ring} when ring != [] ->
        {fast, slow} = Enum.min_max_by(rates, &Lab.rate_bps/1) |> then(fn {s, f} -> {f, s} end)

        # Per delay, the median over rounds of the ratio within a round.
        ratios =
          for %{rate: ^slow, delay: d, rounds: rounds} <- ring do
            per_round = Enum.map(rounds, &(&1[slow] / &1[fast]))
            {d, per_round |> Enum.sort() |> Enum.at(div(length(per_round), 2)), per_round}
          end

        worst = ratios |> Enum.map(&elem(&1, 1)) |> Enum.max()

        IO.puts(
          "  the ring's makespan at #{slow} / at #{fast} (median of the rounds' ratios; each round's): " <>
            Enum.map_join(ratios, ", ", fn {d, x, all} ->
              "#{fmt(x)} at #{fmt(d)} ms (#{Enum.map_join(all, " ", &fmt/1)})"
            end) <>
            " (target 1.25): #{verdict.(worst <= 1.25)}"
        )

      _ ->
        :ok
    end

    worst = empties |> Enum.map(&round_trips/1) |> Enum.max()
    slack = empties |> Enum.map(&(3 * &1.rtt + 10 - &1.wall)) |> Enum.min()

    IO.puts(
      "  an empty job, call to return: at most #{fmt(worst)} round trips + 10 ms, " <>
        "at least #{fmt(slack)} ms under 3 round trips + 10 ms " <>
        "(target 3 round trips + 10 ms): #{verdict.(slack >= 0)}"
    )

    IO.puts(
      "  every image byte-identical to the local render: #{if identical, do: "yes", else: "NO"}"
    )
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

  defp fmt(x), do: :erlang.float_to_binary(x / 1, decimals: 3)
  defp fmt1(x), do: :erlang.float_to_binary(x / 1, decimals: 1)
  defp int(x), do: Integer.to_string(round(x))
end
