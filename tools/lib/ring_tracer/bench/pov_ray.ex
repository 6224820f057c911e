defmodule RingTracer.Bench.PovRay do
  @moduledoc false
  # POV-Ray 3.7 as the benchmarks' reference: whether it is installed, where
  # the `.pov` files of the SPD scenes are, and its own parse and trace times.

  import RingTracer.Bench, only: [median: 1]

  @doc "The SPD scenes the benchmarks run by default (`priv/scenes/spd`)."
  @spec spd_scenes() :: [String.t()]
  def spd_scenes, do: ~w(balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11)

  @doc "The folder of the matching `.pov` files unless `--pov-dir` says otherwise."
  @spec default_dir() :: Path.t()
  def default_dir, do: "../shared/scenes/spd/pov"

  @doc "The `povray` executable, or nil."
  @spec executable() :: String.t() | nil
  def executable, do: System.find_executable("povray")

  @doc """
  POV-Ray's parse (with bounding) and trace times of `file`, medians of
  `runs` renders at `size` x `size` on `threads` threads, in microseconds;
  nil without POV-Ray or without the file.
  """
  @spec times(String.t() | nil, Path.t(), pos_integer(), pos_integer(), pos_integer()) ::
          %{
            parse_us: non_neg_integer(),
            trace_us: non_neg_integer(),
            trace_cpu_us: non_neg_integer()
          }
          | nil
  def times(nil, _file, _size, _threads, _runs), do: nil

  def times(povray, file, size, threads, runs) do
    if File.exists?(file) do
      dir = RingTracer.Bench.private_tmp_dir!("ringtracer-bench-pov")
      out = Path.join(dir, "pov.png")

      samples =
        for _ <- 1..runs do
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

          parse(text)
        end

      File.rm_rf(dir)

      %{
        parse_us: median(Enum.map(samples, & &1.parse_us)),
        trace_us: median(Enum.map(samples, & &1.trace_us)),
        trace_cpu_us: median(Enum.map(samples, & &1.trace_cpu_us))
      }
    end
  end

  @doc """
  The parse (with bounding) and trace times in POV-Ray's report, in
  microseconds, and the CPU time its trace threads used together (which
  other programs on the machine take nothing from); a time it does not
  report counts 0.

      iex> RingTracer.Bench.PovRay.parse(\"""
      ...> Parse Time:    0 hours  0 minutes  0 seconds (0.120 seconds)
      ...>             using 1 thread(s) with 0.024 CPU-seconds total
      ...> Bounding Time: 0 hours  0 minutes  0 seconds (0.005 seconds)
      ...>             using 1 thread(s) with 0.002 CPU-seconds total
      ...> Trace Time:    0 hours  0 minutes  1 seconds (1.500 seconds)
      ...>             using 2 thread(s) with 2.900 CPU-seconds total
      ...> \""")
      %{parse_us: 125_000, trace_us: 1_500_000, trace_cpu_us: 2_900_000}
  """
  @spec parse(String.t()) :: %{
          parse_us: non_neg_integer(),
          trace_us: non_neg_integer(),
          trace_cpu_us: non_neg_integer()
        }
  def parse(text) do
    %{
      parse_us: seconds(text, "Parse Time") + seconds(text, "Bounding Time"),
      trace_us: seconds(text, "Trace Time"),
      trace_cpu_us: cpu_seconds(text, "Trace Time")
    }
  end

  defp cpu_seconds(text, label) do
    case Regex.run(~r/#{label}:[^\n]*\n\s*using \d+ thread\(s\) with ([0-9.]+) CPU-seconds/, text) do
      [_, s] -> round(String.to_float(s) * 1_000_000)
      nil -> 0
    end
  end

  defp seconds(text, label) do
    case Regex.run(~r/#{label}:[^(]*\(([0-9.]+) seconds\)/, text) do
      [_, s] -> round(String.to_float(s) * 1_000_000)
      nil -> 0
    end
  end
end
