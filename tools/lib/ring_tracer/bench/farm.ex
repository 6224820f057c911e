defmodule RingTracer.Bench.Farm do
  @help """
  A farm's queue against its ideal, and how soon a worker that joins works.

      mix ring_tracer.bench farm [--runs 3] [--speeds 2,3,4,6] [--joiners 3,4]

  A head in this VM (`RingTracer.Farm.start_head/1`, a folder of its own),
  one worker peer per `--speeds` factor (each emulating a machine that many
  times slower, one child a job) and a queue of 10 jobs from two users:
  five sequences (`priv/scenes/whitted_orbit.toml`, frames 1-6, 320x240)
  and five stills (`balls_s2.nff`, 512x512). Once the first frame is done,
  one worker per `--joiners` factor joins (its VM started before, so its
  boot is not counted). Rows:

    * **queue**: first submission to the last job's end, against the
      ideal: the atoms' trace time (`[:ring_tracer, :atom, :stop]`'s
      `trace_us`, summed) spread over the workers' capacity, min(2 cores,
      the sum of 1/speed), which grows when the joiners join
    * **join to first atom**: from a joiner's `RingTracer.Farm.join/2` to
      the first atom of a child of its node reaching the job's parent, the
      slower of the joiners (target: under 1 s)

  Medians of `--runs` runs, each on fresh peers.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench

  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "farm [--runs 3] [--speeds 2,3,4,6] [--joiners 3,4]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv, strict: [runs: :integer, speeds: :string, joiners: :string])

    runs = opts[:runs] || 3
    speeds = numbers(opts[:speeds] || "2,3,4,6")
    joiners = numbers(opts[:joiners] || "3,4")
    Mix.Task.run("app.start")
    Peers.ensure_distributed()

    info(
      "farm: 10 jobs (5 x 6 frames of whitted_orbit at 320x240, 5 stills of balls_s2 at 512x512) " <>
        "from 2 users on #{length(speeds)} workers (speeds #{Enum.join(speeds, ",")}), " <>
        "#{length(joiners)} joining after the first frame (speeds #{Enum.join(joiners, ",")}); " <>
        "median of #{runs}; #{vm()}"
    )

    results = for _ <- 1..runs, do: once(speeds, joiners)
    ratio = median(Enum.map(results, & &1.ratio))
    made = median(Enum.map(results, & &1.makespan_ms))
    ideal = median(Enum.map(results, & &1.ideal_ms))
    joins = Enum.map(results, & &1.join_ms)

    join = if Enum.any?(joins, &is_nil/1), do: nil, else: median(joins)

    rows = [
      ["queue", fmt(made / 1000), fmt(ideal / 1000), fmt(ratio), "-", "-"],
      [
        "join to first atom",
        join && fmt(join / 1000),
        "-",
        "-",
        "< 1.000 s",
        join && if(join < 1000, do: "ok", else: "MISSED")
      ]
    ]

    print_table(~w(row measured_s ideal_s ratio target verdict), rows)

    info(
      "runs: " <>
        Enum.map_join(results, "; ", fn r ->
          "ratio #{fmt(r.ratio)}, join #{if r.join_ms, do: "#{r.join_ms} ms", else: "-"}"
        end)
    )
  end

  defp numbers(text),
    do: text |> String.split(",", trim: true) |> Enum.map(&String.to_integer(String.trim(&1)))

  defp once(speeds, joiners) do
    dir = Path.join(private_tmp_dir!("rt_bench_farm"), "head")
    {:ok, _} = Farm.start_head(dir: dir)
    workers = for {s, i} <- Enum.with_index(speeds), do: {Peers.start("bf#{i}"), s}
    late = for {s, i} <- Enum.with_index(joiners), do: {Peers.start("bj#{i}"), s}

    for {{p, n}, s} <- workers,
        do: {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 1, speed: s]])

    wait_workers(length(speeds))
    # Atoms are counted by a process of their own, not in this mailbox.
    collector = spawn_link(fn -> collect([]) end)
    handler = {__MODULE__, make_ref()}

    :ok =
      RingTracer.Telemetry.attach(
        handler,
        [:ring_tracer, :atom, :stop],
        fn _, m, md, _ -> send(collector, {:atom, now(), m.trace_us, md[:node]}) end,
        nil
      )

    t0 = now()
    ids = submit_queue()
    {t_join, joined} = join_after_first_frame(ids, late)
    t_end = wait_all(ids)
    RingTracer.Telemetry.detach(handler)
    send(collector, {:give, self()})
    atoms = receive(do: ({:atoms, atoms} -> atoms))

    work_us = atoms |> Enum.map(&elem(&1, 2)) |> Enum.sum()
    c1 = min(2.0, Enum.sum(Enum.map(speeds, &(1 / &1))))
    c2 = min(2.0, c1 + Enum.sum(Enum.map(joiners, &(1 / &1))))
    ideal_ms = ideal(work_us / 1000, c1, c2, t_join - t0)

    first =
      for n <- joined do
        Enum.find_value(Enum.reverse(atoms), fn {:atom, at, _, node} -> if node == n, do: at end)
      end

    join_ms = if Enum.all?(first, & &1), do: Enum.max(first) - t_join, else: nil

    Enum.each(workers ++ late, fn {{p, _}, _} -> Peers.stop(p) end)
    Farm.stop_head()
    File.rm_rf!(Path.dirname(dir))
    # The next run's head numbers its jobs from 1 again: nothing of this
    # one's may be left here.
    flush()

    makespan = t_end - t0
    %{makespan_ms: makespan, ideal_ms: ideal_ms, ratio: makespan / ideal_ms, join_ms: join_ms}
  end

  defp flush do
    receive do
      {Farm, _, _} -> flush()
    after
      0 -> :ok
    end
  end

  # Work W at capacity c1 until the join at tj, then c2.
  defp ideal(w, c1, c2, tj) do
    if w <= c1 * tj, do: w / c1, else: tj + (w - c1 * tj) / c2
  end

  defp submit_queue do
    orbit = "priv/scenes/whitted_orbit.toml"
    balls = "priv/scenes/balls_s2.nff"

    for i <- 1..10 do
      user = if rem(i, 2) == 0, do: "ann", else: "bob"

      {:ok, id} =
        if i <= 5,
          do: Farm.submit(node(), orbit, width: 320, height: 240, frames: 1..6, user: user),
          else: Farm.submit(node(), balls, width: 512, height: 512, user: user)

      id
    end
  end

  defp join_after_first_frame(ids, late) do
    :ok = Farm.subscribe(node(), hd(ids))

    receive do
      {Farm, _, {:frame, _}} -> :ok
    after
      60_000 -> raise "no frame in 60 s"
    end

    t = now()

    joined =
      for {{p, n}, s} <- late do
        {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 1, speed: s]])
        n
      end

    {t, joined}
  end

  defp wait_workers(count) do
    Enum.reduce_while(1..500, nil, fn _, _ ->
      case Farm.workers(node()) do
        {:ok, ws} when length(ws) >= count ->
          {:halt, :ok}

        _ ->
          Process.sleep(10)
          {:cont, nil}
      end
    end) || raise "workers did not join"
  end

  # The last job's end as the head recorded it (fetching frames is not counted).
  defp wait_all(ids) do
    ids
    |> Enum.map(fn id ->
      {:ok, %{state: :done, finished_at: at}} = Farm.wait(node(), id, timeout: 600_000)
      at
    end)
    |> Enum.max()
  end

  defp now, do: System.os_time(:millisecond)

  defp collect(acc) do
    receive do
      {:atom, _, _, _} = a -> collect([a | acc])
      {:give, to} -> send(to, {:atoms, acc})
    end
  end
end
