defmodule RingTracer.Bench do
  @moduledoc false
  # What the benchmarks of `mix ring_tracer.bench` share: the behaviour each
  # benchmark module implements, and the helpers that make their tables
  # (medians, number formats, the VM line, column alignment).
  #
  # A benchmark is a module under `RingTracer.Bench` with `help/0`, `usage/0`
  # and `run/1`, named by one line in `Mix.Tasks.RingTracer.Bench`'s table.

  @doc "What the benchmark measures and its options: its module's documentation, for `mix help`."
  @callback help() :: String.t()

  @doc "The benchmark's command line, after `mix ring_tracer.bench`, e.g. `\"kernel [--runs R]\"`."
  @callback usage() :: String.t()

  @doc "Runs the benchmark with the command-line arguments that follow its name, printing its table."
  @callback run([String.t()]) :: any()

  @doc """
  The middle element of `list` once sorted (the upper one of an even count).

      iex> RingTracer.Bench.median([3, 1, 2])
      2
      iex> RingTracer.Bench.median([4, 1, 3, 2])
      3
  """
  @spec median([number()]) :: number()
  def median(list), do: Enum.at(Enum.sort(list), div(length(list), 2))

  @doc """
  The median of `runs` calls of `fun` (each `{:ok, result}`), by makespan
  over ideal time (`:elapsed_us / :ideal_us`).
  """
  @spec median_result(pos_integer(), (() -> {:ok, map()})) :: map()
  def median_result(runs, fun) do
    results = for _ <- 1..runs, do: elem(fun.(), 1)
    sorted = Enum.sort_by(results, &(&1.elapsed_us / max(&1.ideal_us, 1)))
    Enum.at(sorted, div(runs, 2))
  end

  @doc """
  A number with three decimals.

      iex> RingTracer.Bench.fmt(2)
      "2.000"
      iex> RingTracer.Bench.fmt(1 / 3)
      "0.333"
  """
  @spec fmt(number()) :: String.t()
  def fmt(x), do: :erlang.float_to_binary(x / 1, decimals: 3)

  @doc """
  Microseconds as seconds with three decimals.

      iex> RingTracer.Bench.secs(1_234_567)
      "1.235"
  """
  @spec secs(number()) :: String.t()
  def secs(us), do: fmt(us / 1_000_000)

  @doc """
  The VM the figures come from: its schedulers, and the flags that decide
  whether idle schedulers spin (`bin/ringtracer` sets them in ERL_FLAGS).
  """
  @spec vm() :: String.t()
  def vm do
    flags =
      case System.get_env("ERL_FLAGS", "") do
        "" -> "ERL_FLAGS unset"
        f -> "ERL_FLAGS #{inspect(f)}"
      end

    "#{System.schedulers_online()} schedulers, " <>
      "#{:erlang.system_info(:dirty_cpu_schedulers_online)} dirty CPU schedulers, #{flags}"
  end

  @doc """
  A table's lines: every cell right-aligned in its column, columns two
  spaces apart, `nil` cells shown as `-`.

      iex> RingTracer.Bench.table_lines(~w(name value), [["a", "1.000"], ["long", nil]])
      ["name  value", "   a  1.000", "long      -"]
  """
  @spec table_lines([String.t()], [[String.t() | nil]]) :: [String.t()]
  def table_lines(header, rows) do
    rows = Enum.map(rows, fn r -> Enum.map(r, &(&1 || "-")) end)

    widths =
      Enum.map(Enum.zip([header | rows]), fn col ->
        col |> Tuple.to_list() |> Enum.map(&String.length/1) |> Enum.max()
      end)

    for row <- [header | rows] do
      row
      |> Enum.zip(widths)
      |> Enum.map_join("  ", fn {cell, w} -> String.pad_leading(cell, w) end)
    end
  end

  @doc "Prints `table_lines/2` through the Mix shell."
  @spec print_table([String.t()], [[String.t() | nil]]) :: :ok
  def print_table(header, rows) do
    Enum.each(table_lines(header, rows), &info/1)
  end

  @doc "Prints a line through the Mix shell."
  @spec info(String.t()) :: :ok
  def info(line), do: Mix.shell().info(line)

  @doc """
  A new folder of this run's own under the system's temporary folder, that
  only this user can enter: a random name that `mkdir` must create (never a
  folder someone else made there first, nor a symlink planted in its
  place), closed to others before anything is put in it.

      iex> dir = RingTracer.Bench.private_tmp_dir!("ringtracer-doc")
      iex> Bitwise.band(File.stat!(dir).mode, 0o777)
      0o700
      iex> File.rmdir(dir)
      :ok
  """
  @spec private_tmp_dir!(String.t()) :: Path.t()
  def private_tmp_dir!(prefix) do
    name = prefix <> "-" <> Base.url_encode64(:crypto.strong_rand_bytes(9), padding: false)
    dir = Path.join(System.tmp_dir!(), name)
    :ok = RingTracer.Output.private_dir(dir)
    dir
  end
end
