defmodule RingTracer.Bench.Preview do
  @help """
  What watching costs: a render's makespan with a live preview and one
  browser-like viewer reading its event stream (`viewer/2`, an SSE client
  on `:httpc`), against the same render without a preview; runs alternate,
  and the row gives the medians and their ratio (the target is at most
  1.03).

      mix ring_tracer.bench preview [--runs 9] [--width 512] [--height 512] [--children N]
                                    [--atoms 16] [--scene priv/scenes/balls_s1.nff]

  From iex, `RingTracer.Bench.Preview.measure/1` takes the same as a
  keyword list, and also `:samples`, `:depth`, `:speeds` and `:strategy`
  as for `RingTracer.render/2`; defaults: the scene's own 512 x 512,
  schedulers-online children, 16 atoms per child, 9 runs of each.
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  @switches [
    runs: :integer,
    width: :integer,
    height: :integer,
    children: :integer,
    atoms: :integer,
    scene: :string
  ]

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "preview [--runs 9] [--width 512] [--height 512] [--children N] [--atoms 16]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} = OptionParser.parse(argv, strict: @switches)
    measure(opts)
  end

  @doc "Runs the benchmark, prints its row and returns the figures."
  @spec measure(keyword()) :: map()
  def measure(opts \\ []) do
    {:ok, _} = Application.ensure_all_started(:ring_tracer)
    {:ok, _} = Application.ensure_all_started(:inets)
    scene = Keyword.get(opts, :scene, "priv/scenes/balls_s1.nff")
    runs = Keyword.get(opts, :runs, 9)

    render_opts =
      [
        width: Keyword.get(opts, :width, 512),
        height: Keyword.get(opts, :height, 512),
        children: Keyword.get(opts, :children, System.schedulers_online()),
        atoms: Keyword.get(opts, :atoms, 16)
      ] ++ Keyword.take(opts, [:samples, :depth, :speeds, :strategy])

    # One of each first, not counted: caches, the kernel, inets warm.
    _ = plain(scene, render_opts)
    _ = watched(scene, render_opts)

    {without, with} =
      Enum.reduce(1..runs, {[], []}, fn _, {a, b} ->
        {[plain(scene, render_opts) | a], [watched(scene, render_opts) | b]}
      end)

    row = %{
      runs: runs,
      without_ms: median(without) / 1000,
      with_ms: median(with) / 1000,
      ratio: median(with) / median(without),
      # Each watched run against the plain run just before it: the pair
      # shares the machine's load of the moment (it is shared here).
      pair_ratio: median(Enum.zip_with(with, without, &(&1 / &2)))
    }

    IO.puts(
      "preview: #{Keyword.get(render_opts, :width)}x#{Keyword.get(render_opts, :height)}, " <>
        "#{render_opts[:children]} children x #{render_opts[:atoms]} atoms, #{runs} runs each: " <>
        "makespan median #{Float.round(row.without_ms, 1)} ms without, " <>
        "#{Float.round(row.with_ms, 1)} ms with a preview and one viewer " <>
        "(#{Float.round(row.ratio, 3)}x; median of the pairs' ratios #{Float.round(row.pair_ratio, 3)}x)"
    )

    row
  end

  defp plain(scene, opts) do
    {:ok, r} = RingTracer.render(scene, opts)
    r.elapsed_us
  end

  defp watched(scene, opts) do
    {:ok, preview} = RingTracer.Preview.start()
    me = self()
    viewer = spawn_link(fn -> send(me, {:viewed, self(), viewer(preview.url <> "events")}) end)
    # The browser is there when the job starts (its connecting is not the job's).
    connected(preview, 500)
    {:ok, r} = RingTracer.render(scene, Keyword.put(opts, :preview, preview))

    receive do
      {:viewed, ^viewer, {:ok, frames}} when frames > 0 -> :ok
    after
      30_000 -> raise "the viewer did not see the job's end"
    end

    RingTracer.Preview.stop(preview)
    r.elapsed_us
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
