defmodule RingTracer.Bench.Preview do
  @help """
  What watching costs: a render's makespan with a live preview and one
  viewer reading its whole event stream, against the same render without a
  preview, in alternating pairs (the order flips from pair to pair, so both
  sides see the same drift of the machine's speed).

      mix ring_tracer.bench preview [--pairs 241] [--width 2048] [--height 2048]
                                    [--children N] [--atoms 16] [--samples 1]
                                    [--scene priv/scenes/balls_s1.nff] [--viewer curl|httpc]

  The viewer is `curl` in an OS process of its own (`--viewer curl`, the
  default when curl is installed): it runs on this machine and takes its
  share of the cores, as a browser would, but its own CPU time is not the
  VM's; `--viewer httpc` reads the stream from inside the VM instead
  (`viewer/2`, an SSE client on `:httpc`).

  Each render starts after the same 200 ms pause. Printed: the medians of
  the makespans; the median of the pairs' ratios (with a preview over
  without) with its 95% confidence interval (bootstrap, 10,000 resamples
  of the pairs); the CPU time the VM used during the job
  (`:erlang.statistics(:runtime)`, every thread, the NIF's dirty
  schedulers included) without a preview, and the share the preview added
  to it (its server, the HTTP server, the stream's handler, the job's
  sends to it), median and interval over the pairs; the time the
  preview's own processes spent on a scheduler during the job (traced), as
  a share of the job's CPU time (an upper bound on a loaded machine: it
  includes moments the OS took a scheduler's thread away); then the
  target, met only if the makespan interval's upper bound is at most 1.03.

  From iex, `RingTracer.Bench.Preview.measure/1` takes the same as a
  keyword list (`:viewer` an atom), and also `:depth`, `:speeds` and
  `:strategy` as for `RingTracer.render/2`; defaults: the scene's own view
  at 2048 x 2048 (a job of about 0.7 s of CPU time here),
  schedulers-online children, 16 atoms per child, 241 pairs (about ten
  minutes here; with fewer, the interval is too wide to decide the 3%
  target).
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench, only: [fmt: 1, info: 1]

  alias RingTracer.Bench.Targets

  @switches [
    pairs: :integer,
    runs: :integer,
    width: :integer,
    height: :integer,
    children: :integer,
    atoms: :integer,
    samples: :integer,
    scene: :string,
    viewer: :string
  ]
  @resamples 10_000
  @bound 1.03
  @settle_ms 200

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage,
    do:
      "preview [--pairs 241] [--width 2048] [--height 2048] [--children N] [--atoms 16] [--viewer curl|httpc]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} = OptionParser.parse(argv, strict: @switches)

    opts =
      opts
      |> Keyword.update(:viewer, nil, &viewer_option/1)
      |> Keyword.put_new(:pairs, opts[:runs])
      |> Enum.reject(&(elem(&1, 1) == nil))

    measure(opts)
  end

  defp viewer_option("curl"), do: :curl
  defp viewer_option("httpc"), do: :httpc
  defp viewer_option(other), do: Mix.raise("--viewer takes curl or httpc, not #{other}")

  @doc "Runs the benchmark, prints its row and target, and returns the figures."
  @spec measure(keyword()) :: map()
  def measure(opts \\ []) do
    {:ok, _} = Application.ensure_all_started(:ring_tracer)
    {:ok, _} = Application.ensure_all_started(:inets)
    scene = Keyword.get(opts, :scene, "priv/scenes/balls_s1.nff")
    pairs = Keyword.get(opts, :pairs, 241)
    viewer = Keyword.get_lazy(opts, :viewer, fn -> if curl(), do: :curl, else: :httpc end)

    render_opts =
      [
        width: Keyword.get(opts, :width, 2048),
        height: Keyword.get(opts, :height, 2048),
        children: Keyword.get(opts, :children, System.schedulers_online()),
        atoms: Keyword.get(opts, :atoms, 16)
      ] ++ Keyword.take(opts, [:samples, :depth, :speeds, :strategy])

    # One of each first, not counted: caches, the kernel, inets warm.
    _ = plain(scene, render_opts)
    _ = watched(scene, render_opts, viewer)

    runs =
      for i <- 1..pairs do
        if rem(i, 2) == 1 do
          p = plain(scene, render_opts)
          {p, watched(scene, render_opts, viewer)}
        else
          w = watched(scene, render_opts, viewer)
          {plain(scene, render_opts), w}
        end
      end

    ratios = for {p, w} <- runs, do: w.us / p.us
    extra_cpu = for {p, w} <- runs, do: (w.cpu_ms - p.cpu_ms) / max(p.cpu_ms, 1)
    {lo, hi} = median_ci(ratios, @resamples)
    {cpu_lo, cpu_hi} = median_ci(extra_cpu, @resamples)
    own = for {_, w} <- runs, do: w.own_us / max(w.cpu_ms * 1000, 1)
    {own_lo, own_hi} = median_ci(own, @resamples)

    row = %{
      pairs: pairs,
      viewer: viewer,
      without_ms: median(for({p, _} <- runs, do: p.us)) / 1000,
      with_ms: median(for({_, w} <- runs, do: w.us)) / 1000,
      pair_ratio: median(ratios),
      ci: {lo, hi},
      cpu_ms: median(for({p, _} <- runs, do: p.cpu_ms)),
      extra_cpu: median(extra_cpu),
      extra_cpu_ci: {cpu_lo, cpu_hi},
      own: median(own),
      own_ci: {own_lo, own_hi}
    }

    label =
      "#{render_opts[:width]}x#{render_opts[:height]} #{Path.basename(scene)}, " <>
        "#{render_opts[:children]} children x #{render_opts[:atoms]} atoms"

    info(
      "preview: #{label}, #{pairs} pairs in alternating order, viewer #{viewer_name(viewer)}\n" <>
        "  makespan median #{ms(row.without_ms)} ms without, #{ms(row.with_ms)} ms with a preview and one viewer\n" <>
        "  median of the pairs' ratios #{fmt(row.pair_ratio)}x, 95% CI #{fmt(lo)}-#{fmt(hi)} " <>
        "(bootstrap, #{@resamples} resamples)\n" <>
        "  VM CPU time during the job: median #{row.cpu_ms} ms without; added by the preview " <>
        "#{pct(row.extra_cpu)} of it, 95% CI #{pct(cpu_lo)} to #{pct(cpu_hi)}\n" <>
        "  the preview's own processes on a scheduler during the job: median #{pct(row.own)} " <>
        "of the job's CPU time, 95% CI #{pct(own_lo)} to #{pct(own_hi)}"
    )

    target = %{
      name: :preview_makespan,
      text:
        "a preview and one viewer add at most 3% to the makespan " <>
          "(upper 95% bound of the median pair ratio <= #{@bound})",
      goal?: true,
      scenarios: {:one, label},
      check: {:at_most, "preview", :ratio_hi, @bound}
    }

    lines = Targets.lines([target], [], [%{scenario: label, strategy: "preview", ratio_hi: hi}])
    info("targets:\n" <> Enum.map_join(lines, "\n", &("  " <> &1)))
    Map.put(row, :met, hi <= @bound)
  end

  @doc """
  The median of `values` and its 95% percentile-bootstrap confidence
  interval from `resamples` resamples (a fixed seed: the same values give
  the same interval).

      iex> {lo, hi} = RingTracer.Bench.Preview.median_ci([1.0, 1.1, 0.9, 1.0, 1.05, 0.95, 1.0], 2000)
      iex> lo <= 1.0 and 1.0 <= hi
      true
  """
  @spec median_ci([number()], pos_integer()) :: {float(), float()}
  def median_ci(values, resamples) do
    tuple = List.to_tuple(values)
    n = tuple_size(tuple)

    {medians, _} =
      Enum.map_reduce(1..resamples, :rand.seed_s(:exsss, {22, 3, 103}), fn _, seed ->
        {sample, seed} =
          Enum.map_reduce(1..n, seed, fn _, s ->
            {i, s} = :rand.uniform_s(n, s)
            {elem(tuple, i - 1), s}
          end)

        {median(sample), seed}
      end)

    sorted = medians |> Enum.sort() |> List.to_tuple()
    at = fn q -> elem(sorted, min(round(q * (resamples - 1)), resamples - 1)) / 1 end
    {at.(0.025), at.(0.975)}
  end

  defp ms(x), do: :erlang.float_to_binary(x / 1, decimals: 1)
  defp pct(x), do: :erlang.float_to_binary(x * 100, decimals: 2) <> "%"

  defp viewer_name(:curl), do: "curl (an OS process of its own)"
  defp viewer_name(:httpc), do: ":httpc (in the VM)"

  defp curl, do: System.find_executable("curl")

  # Each render starts after the same pause on both sides: on a shared
  # machine, threads that slept longer get the cores first, and the side
  # with set-up to do would otherwise start rested.
  defp plain(scene, opts) do
    Process.sleep(@settle_ms)
    timed(fn -> RingTracer.render(scene, opts) end)
  end

  defp watched(scene, opts, viewer) do
    {:ok, preview} = RingTracer.Preview.start()
    url = preview.url <> "events"
    watching = start_viewer(viewer, url)
    # The viewer is there when the job starts (its connecting is not the job's).
    connected(preview, 2_500)
    Process.sleep(@settle_ms)
    tracer = trace(preview)
    run = timed(fn -> RingTracer.render(scene, Keyword.put(opts, :preview, preview)) end)
    own_us = untrace(tracer)
    :ok = await_viewer(watching)
    RingTracer.Preview.stop(preview)
    Map.put(run, :own_us, own_us)
  end

  # The time the preview's own processes (its server, the HTTP server's
  # processes and the stream's handler) spend on a scheduler while traced:
  # what they cost the VM, the job's sends to them aside.
  defp trace(preview) do
    tracer = spawn(fn -> tracing(%{}, MapSet.new(), 0) end)
    {:links, links} = Process.info(preview.pid, :links)
    flags = [:running, :set_on_spawn, :monotonic_timestamp, {:tracer, tracer}]
    pids = [preview.pid | Enum.flat_map(links, &if(is_pid(&1), do: tree(&1), else: []))]
    Enum.each(pids, &set_trace(&1, true, flags))
    {tracer, pids}
  end

  defp untrace({tracer, pids}) do
    ref = make_ref()
    send(tracer, {:seen, self(), ref})
    seen = receive do: ({^ref, seen} -> seen)
    Enum.each(Enum.uniq(pids ++ seen), &set_trace(&1, false, [:all]))
    # Every trace message is in the tracer's queue once tracing is off.
    send(tracer, {:total, self(), ref})
    total = receive do: ({^ref, native} -> native)
    Process.exit(tracer, :kill)
    System.convert_time_unit(total, :native, :microsecond)
  end

  defp set_trace(pid, on?, flags) do
    :erlang.trace(pid, on?, flags)
  catch
    :error, :badarg -> 0
  end

  # A supervisor and every process under it.
  defp tree(sup) do
    children =
      for {_, pid, type, _} <- Supervisor.which_children(sup), is_pid(pid), do: {pid, type}

    [
      sup
      | Enum.flat_map(children, fn {pid, type} ->
          if type == :supervisor, do: tree(pid), else: [pid]
        end)
    ]
  end

  defp tracing(ins, seen, total) do
    receive do
      {:trace_ts, pid, :in, _, t} ->
        tracing(Map.put(ins, pid, t), MapSet.put(seen, pid), total)

      {:trace_ts, pid, :out, _, t} ->
        {t0, ins} = Map.pop(ins, pid)
        tracing(ins, seen, if(t0, do: total + t - t0, else: total))

      {:seen, from, ref} ->
        send(from, {ref, MapSet.to_list(seen)})
        tracing(ins, seen, total)

      {:total, from, ref} ->
        send(from, {ref, total})
        tracing(ins, seen, total)

      _ ->
        tracing(ins, seen, total)
    end
  end

  # The job's makespan and the CPU time the VM used during the render.
  defp timed(fun) do
    {cpu0, _} = :erlang.statistics(:runtime)
    {:ok, r} = fun.()
    {cpu1, _} = :erlang.statistics(:runtime)
    %{us: r.elapsed_us, cpu_ms: cpu1 - cpu0}
  end

  defp start_viewer(:curl, url) do
    args = ["--silent", "--no-buffer", "--max-time", "300", "--output", "/dev/null", url]
    {:curl, Port.open({:spawn_executable, curl()}, [:binary, :exit_status, args: args])}
  end

  defp start_viewer(:httpc, url) do
    me = self()
    {:httpc, spawn_link(fn -> send(me, {:viewed, self(), viewer(url)}) end)}
  end

  # curl exits 0 once the stream's last chunk came: the server sends it
  # after the job's end frame.
  defp await_viewer({:curl, port}) do
    receive do
      {^port, {:exit_status, 0}} -> :ok
      {^port, {:exit_status, n}} -> raise "the viewer (curl) exited with #{n}"
    after
      300_000 -> raise "the viewer did not see the job's end"
    end
  end

  defp await_viewer({:httpc, pid}) do
    receive do
      {:viewed, ^pid, {:ok, frames}} when frames > 0 -> :ok
    after
      300_000 -> raise "the viewer did not see the job's end"
    end
  end

  @doc """
  Reads the Server-Sent Events stream at `url` (a preview's `/events`) until
  its `end` frame, as a browser would; returns `{:ok, frames_seen}` or
  `{:error, reason}`. `timeout` bounds the wait for each piece.
  """
  @spec viewer(String.t(), timeout()) :: {:ok, non_neg_integer()} | {:error, term()}
  def viewer(url, timeout \\ 30_000) do
    {:ok, ref} =
      :httpc.request(:get, {String.to_charlist(url), []}, [], sync: false, stream: :self)

    read(ref, "", 0, timeout)
  end

  defp read(ref, buffer, frames, timeout) do
    receive do
      {:http, {^ref, :stream_start, _headers}} ->
        read(ref, buffer, frames, timeout)

      {:http, {^ref, :stream, data}} ->
        {complete, rest} = split(buffer <> data)
        frames = frames + length(complete)

        if Enum.any?(complete, &String.contains?(&1, "event: end\n")) do
          :httpc.cancel_request(ref)
          {:ok, frames}
        else
          read(ref, rest, frames, timeout)
        end

      {:http, {^ref, :stream_end, _}} ->
        {:error, :ended_early}

      {:http, {^ref, {:error, reason}}} ->
        {:error, reason}
    after
      timeout ->
        :httpc.cancel_request(ref)
        {:error, :timeout}
    end
  end

  # SSE frames end with a blank line; comments (": keep-alive") are not frames.
  defp split(text) do
    parts = String.split(text, "\n\n")
    {complete, [rest]} = Enum.split(parts, -1)
    {Enum.reject(complete, &String.starts_with?(&1, ":")), rest}
  end

  defp connected(_preview, 0), do: raise("the viewer did not connect")

  defp connected(preview, tries) do
    if RingTracer.Preview.viewers(preview) == 0 do
      Process.sleep(2)
      connected(preview, tries - 1)
    end
  end

  defp median(list) do
    sorted = Enum.sort(list)
    n = length(sorted)

    if rem(n, 2) == 1,
      do: Enum.at(sorted, div(n, 2)),
      else: (Enum.at(sorted, div(n, 2) - 1) + Enum.at(sorted, div(n, 2))) / 2
  end
end
