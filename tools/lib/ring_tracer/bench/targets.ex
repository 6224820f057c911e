defmodule RingTracer.Bench.Targets do
  @moduledoc false
  # The targets the balance benchmark checks under its table, in one table,
  # each named by what it measures.
  #
  # A target compares one figure of the table's rows (`:ratio`, makespan
  # over ideal; `:msgs`, messages per atom) in the scenarios it names:
  #
  #   * `{:at_most, strategy, figure, bound}` — the strategy's figure is at
  #     most `bound`;
  #   * `{:below, figure, strategy, other}` — the strategy's figure is below
  #     the other's (`:above`: above it);
  #   * `{:within, figure, strategy, other, margin}` — the strategy's figure
  #     is at most the other's plus `margin`.
  #
  # Scenarios: `:real` (the real scenes), `{:real_except, labels}`, `:all`
  # (real and simulated), or `{:one, label}` (a single row, reported "not run
  # (--quick)" when the run left it out). A target of `goal?: false` is shown
  # for comparison only: "yes" or "no" instead of "ok" or "MISSED". A
  # scenario without the rows a check compares says "no row".

  import RingTracer.Bench, only: [fmt: 1]

  @typedoc "A row of the balance table: scenario, strategy and its figures."
  @type row :: %{
          required(:scenario) => String.t(),
          required(:strategy) => String.t(),
          optional(atom()) => term()
        }

  @type scenarios :: :real | :all | {:real_except, [String.t()]} | {:one, String.t()}
  @type check ::
          {:at_most, String.t(), atom(), number()}
          | {:below | :above, atom(), String.t(), String.t()}
          | {:within, atom(), String.t(), String.t(), number()}
  @type t :: %{
          name: atom(),
          text: String.t(),
          goal?: boolean(),
          scenarios: scenarios(),
          check: check()
        }

  @table [
    %{
      name: :ring_makespan_speeds,
      text: "ring <= 1.04 x ideal on 8 speeds",
      goal?: true,
      scenarios: {:one, "8, speeds 1..8"},
      check: {:at_most, "ring", :ratio, 1.04}
    },
    %{
      name: :ring_makespan_one_slow,
      text: "ring <= 1.03 x ideal with one 4x slower",
      goal?: true,
      scenarios: {:one, "4, one 4x slower"},
      check: {:at_most, "ring", :ratio, 1.03}
    },
    %{
      name: :ring_near_floor,
      text: "ring within 0.02 of the floor",
      goal?: true,
      scenarios: :real,
      check: {:within, :ratio, "ring", "floor", 0.02}
    },
    %{
      name: :ring_split_makespan,
      text: "the ring with adaptive atoms within 0.02 of the floor",
      goal?: false,
      scenarios: :real,
      check: {:within, :ratio, "ring/split", "floor", 0.02}
    },
    %{
      name: :ring_left_makespan,
      text: "the ring with offers to the left only <= 1.10 x ideal",
      goal?: false,
      scenarios: :real,
      check: {:at_most, "ring/left", :ratio, 1.10}
    },
    %{
      name: :ring_interleaved_makespan,
      text: "the ring on interleaved strips <= 1.10 x ideal",
      goal?: false,
      scenarios: :real,
      check: {:at_most, "ring/interleaved", :ratio, 1.10}
    },
    %{
      name: :ring_makespan_many_children,
      text: "ring <= 1.07 x ideal at N=1024",
      goal?: true,
      scenarios: {:one, "simulated N=1024"},
      check: {:at_most, "ring", :ratio, 1.07}
    },
    %{
      name: :static_loses_on_unequal_work,
      text: "static worse than ring (speeds or strips differ)",
      goal?: true,
      scenarios: {:real_except, ["4 equal"]},
      check: {:above, :ratio, "static", "ring"}
    },
    %{
      name: :ring_fewer_messages,
      text: "ring fewer messages per atom than master",
      goal?: true,
      scenarios: :all,
      check: {:below, :msgs, "ring", "master"}
    }
  ]

  @doc "The targets, in the order they are printed."
  @spec table() :: [t()]
  def table, do: @table

  @doc """
  The lines printed under the balance table: one per target, each scenario's
  figures and verdict. `real` lists the real scenarios' labels; the
  simulated ones are the rows' scenarios that start with "simulated".

      iex> rows = [
      ...>   %{scenario: "a", strategy: "ring", ratio: 1.05, msgs: 1.5},
      ...>   %{scenario: "a", strategy: "master", ratio: 1.02, msgs: 2.1}
      ...> ]
      iex> [target] = Enum.filter(RingTracer.Bench.Targets.table(), &(&1.name == :ring_fewer_messages))
      iex> RingTracer.Bench.Targets.lines([target], ["a"], rows)
      ["ring fewer messages per atom than master: a 1.500 vs 2.100 ok"]
  """
  @spec lines([t()], [String.t()], [row()]) :: [String.t()]
  def lines(targets \\ @table, real, rows) do
    sims =
      rows
      |> Enum.map(& &1.scenario)
      |> Enum.filter(&String.starts_with?(&1, "simulated"))
      |> Enum.uniq()

    Enum.map(targets, &line(&1, real, sims, rows))
  end

  @doc "The block printed under the balance table."
  @spec report([String.t()], [row()]) :: String.t()
  def report(real, rows),
    do: "\ntargets:\n" <> Enum.map_join(lines(real, rows), "\n", &("  " <> &1))

  defp line(%{text: text, goal?: goal?} = target, real, sims, rows) do
    prefix = if goal?, do: text, else: "(not a target) " <> text

    body =
      case target.scenarios do
        {:one, label} ->
          if Enum.any?(rows, &(&1.scenario == label)),
            do: " " <> result(target.check, label, rows, goal?),
            else: " not run (--quick)"

        scenarios ->
          Enum.map_join(labels(scenarios, real, sims), ";", fn s ->
            " #{s} " <> result(target.check, s, rows, goal?)
          end)
      end

    prefix <> ":" <> body
  end

  defp labels(:real, real, _sims), do: real
  defp labels(:all, real, sims), do: real ++ sims
  defp labels({:real_except, out}, real, _sims), do: real -- out

  defp result(check, s, rows, goal?) do
    if Enum.all?(compared(check), &(value(rows, s, &1, figure(check)) != nil)),
      do: checked(check, s, rows, goal?),
      else: "no row"
  end

  defp compared({:at_most, strategy, _, _}), do: [strategy]
  defp compared({_, _, strategy, other}), do: [strategy, other]
  defp compared({:within, _, strategy, other, _}), do: [strategy, other]

  defp figure({:at_most, _, figure, _}), do: figure
  defp figure(check), do: elem(check, 1)

  defp checked({:at_most, strategy, figure, bound}, s, rows, goal?) do
    v = value(rows, s, strategy, figure)
    "#{fmt(v)} #{verdict(v <= bound, goal?)}"
  end

  defp checked({order, figure, strategy, other}, s, rows, goal?) when order in [:below, :above] do
    {v, w} = {value(rows, s, strategy, figure), value(rows, s, other, figure)}
    ok = if order == :below, do: v < w, else: v > w
    "#{fmt(v)} vs #{fmt(w)} #{verdict(ok, goal?)}"
  end

  defp checked({:within, figure, strategy, other, margin}, s, rows, goal?) do
    {v, w} = {value(rows, s, strategy, figure), value(rows, s, other, figure)}
    "#{fmt(v)} vs #{fmt(w)} #{verdict(v <= w + margin, goal?)}"
  end

  defp value(rows, scenario, strategy, key),
    do: Enum.find_value(rows, &(&1.scenario == scenario and &1.strategy == strategy and &1[key]))

  defp verdict(true, true), do: "ok"
  defp verdict(false, true), do: "MISSED"
  defp verdict(true, false), do: "yes"
  defp verdict(false, false), do: "no"
end
