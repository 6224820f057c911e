defmodule RingTracer.Strategies do
  @moduledoc """
  The strategies `RingTracer.render/2` knows by name (each a
  `RingTracer.Strategy`):

  | name | module | idea |
  |---|---|---|
  | `:static` | `RingTracer.Strategy.Static` | N strips, no rebalancing (the paper's "divisão simples") |
  | `:master` | `RingTracer.Strategy.Master` | the parent hands out one atom at a time ("divisão complexa") |
  | `:ring` | `RingTracer.Strategy.Ring` | the paper's ring of help offers (default) |
  | `:steal` | `RingTracer.Strategy.Steal` | an idle child steals half of a random sibling's atoms |
  """

  @strategies %{
    static: RingTracer.Strategy.Static,
    master: RingTracer.Strategy.Master,
    ring: RingTracer.Strategy.Ring,
    steal: RingTracer.Strategy.Steal
  }

  @doc """
  The module of a strategy name.

      iex> RingTracer.Strategies.module(:ring)
      {:ok, RingTracer.Strategy.Ring}
      iex> RingTracer.Strategies.module(:lottery)
      :error
  """
  @spec module(atom()) :: {:ok, module()} | :error
  def module(name), do: Map.fetch(@strategies, name)

  @doc "Every strategy name."
  @spec names() :: [atom()]
  def names, do: [:static, :master, :ring, :steal]

  @doc """
  The strategy of `render/2`'s validated options, as a job's spec names it:
  `{module, options}` (as given, if given so), the ring's options taken from `:hold_after`,
  `:split` (adaptive atoms, default false) and `:aim` (by default, a ring aims on strips, see `RingTracer.Strategy.Ring.Aim`).

      iex> RingTracer.Strategies.from_options(strategy: :ring, layout: :strips, aim: nil, hold_after: 16)
      {RingTracer.Strategy.Ring, [hold_after: 16, aim: true, split: false]}
      iex> RingTracer.Strategies.from_options(strategy: :steal, layout: :strips, aim: nil, hold_after: 16)
      {RingTracer.Strategy.Steal, []}
  """
  @spec from_options(keyword()) :: RingTracer.Strategy.t()
  def from_options(opts) do
    case opts[:strategy] do
      {module, options} ->
        {module, options}

      :ring ->
        aim = if opts[:aim] == nil, do: opts[:layout] == :strips, else: opts[:aim]

        {RingTracer.Strategy.Ring,
         [hold_after: opts[:hold_after], aim: aim, split: Keyword.get(opts, :split, false)]}

      name ->
        {:ok, module} = module(name)
        {module, []}
    end
  end
end
