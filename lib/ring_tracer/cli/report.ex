defmodule RingTracer.CLI.Report do
  @moduledoc false
  # What `ringtracer render` prints when a job ends (POV-Ray-style
  # statistics): times, rays by kind, the rate, peak memory, a line per
  # child; for a sequence, a line per frame before them.

  alias RingTracer.{Rays, Result}

  # A child's atom counts on its line; then the strategy's counters
  # (`RingTracer.Strategy.stats/0`), each named without its prefix.
  @atom_counts [:own, :given, :received, :traced]

  @doc """
  The job's statistics: parse and trace times, rays by kind and the rate,
  peak memory, a line per child. Works for a sequence's result too (no
  pixels).
  """
  @spec statistics(Result.t(), non_neg_integer()) :: iodata()
  def statistics(%Result{} = result, load_us) do
    r = result.rays
    rays = Rays.total(r)
    secs = (result.elapsed_us || 0) / 1_000_000
    children = result.children || []

    lines =
      for c <- children do
        node = if c.node != node(), do: " on #{c.node}", else: ""

        "  child #{c.index}#{node}: #{counts(c, @atom_counts, "")}; " <>
          "offers #{counts(c, RingTracer.Strategy.stats(), "offers_")}\n"
      end

    [
      "parse #{seconds(load_us / 1_000_000)}, trace #{seconds(secs)} with #{length(children)} children\n",
      "rays: #{rays} (eye #{r.eye}, #{r.eye_hits} hit; reflected #{r.reflected}; ",
      "refracted #{r.refracted}; shadow #{r.shadow}), #{mrays(rays, secs)} Mrays/s\n",
      peak_memory(),
      lines
    ]
  end

  # "own 4, given 1": each count of `keys` in `stats`, named without `prefix`.
  defp counts(stats, keys, prefix),
    do:
      Enum.map_join(
        keys,
        ", ",
        &"#{String.replace_prefix(to_string(&1), prefix, "")} #{Map.get(stats, &1)}"
      )

  @doc "A line for each report file of `opts` (`--stats`, `--timeline`, `--ownership`)."
  @spec reports_written(keyword()) :: iodata()
  def reports_written(opts),
    do: for(k <- [:stats, :timeline, :ownership], p = opts[k], do: "wrote #{p}\n")

  @doc """
  A line for a frame of a sequence (a summary: `:number`, `:completed_us`,
  `:elapsed_us`, `:atoms`, `:rays`): its number, when its last pixel came
  (from the job's start), its time in the ring from its release to then
  (frames overlap: a sequence keeps several in flight), its atoms and rays,
  and its file.

      iex> frame = %{number: 7, completed_us: 1_750_000, elapsed_us: 250_000, atoms: 64, rays: 1234}
      iex> IO.iodata_to_binary(RingTracer.CLI.Report.frame(frame, "f_0007.png"))
      "  frame 7: done at 1.750 s (0.250 s in flight), 64 atoms, 1234 rays, f_0007.png\\n"
  """
  @spec frame(map(), Path.t()) :: iodata()
  def frame(frame, path) do
    done = if us = frame[:completed_us], do: "done at #{seconds(us / 1_000_000)} ", else: ""
    time = if us = frame.elapsed_us, do: seconds(us / 1_000_000), else: "? s"

    "  frame #{frame.number}: #{done}(#{time} in flight), #{count(frame.atoms)} atoms, " <>
      "#{rays(frame.rays)} rays, #{path}\n"
  end

  @doc """
  The sequence's pace: its makespan over its frames.

      iex> RingTracer.CLI.Report.pace(2_400_000, 24)
      "0.100 s per frame"
  """
  @spec pace(non_neg_integer(), pos_integer()) :: String.t()
  def pace(elapsed_us, frames), do: "#{seconds(elapsed_us / 1_000_000 / frames)} per frame"

  defp count(n) when is_integer(n), do: n
  defp count(list) when is_list(list), do: length(list)
  defp count(map) when is_map(map), do: map_size(map)
  defp count(_), do: "?"

  defp rays(n) when is_integer(n), do: n
  defp rays(%{eye: _} = r), do: Rays.total(r)
  defp rays(_), do: "?"

  @doc "`s` seconds as text, to the millisecond."
  @spec seconds(number()) :: String.t()
  def seconds(s), do: :erlang.float_to_binary(s / 1, decimals: 3) <> " s"

  defp mrays(rays, secs),
    do: :erlang.float_to_binary(rays / max(secs, 1.0e-6) / 1.0e6, decimals: 2)

  # The process's peak resident memory (Linux), else the VM's current total.
  defp peak_memory do
    kb =
      case File.read("/proc/self/status") do
        {:ok, status} ->
          case Regex.run(~r/VmHWM:\s+(\d+) kB/, status) do
            [_, kb] -> String.to_integer(kb)
            _ -> nil
          end

        _ ->
          nil
      end

    mib = if kb, do: kb / 1024, else: :erlang.memory(:total) / 1_048_576
    # Run by `ringtracer serve`, the process is the server, which outlives the job.
    whose =
      if RingTracer.CLI.Console.get().cwd, do: " (the server's, over all its renders)", else: ""

    "peak memory #{:erlang.float_to_binary(mib, decimals: 1)} MiB#{whose}\n"
  end
end
