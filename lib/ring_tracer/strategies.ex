defmodule RingTracer.Strategies do
  @moduledoc false
  # The strategies `RingTracer.render/2` knows by name (each a
  # `RingTracer.Strategy`):
  #
  # | name | module | idea |
  # |---|---|---|
  # | `:static` | `RingTracer.Strategy.Static` | N strips, no rebalancing (the paper's "divisão simples") |
  # | `:master` | `RingTracer.Strategy.Master` | the parent hands out one atom at a time ("divisão complexa") |
  # | `:ring` | `RingTracer.Strategy.Ring` | the paper's ring of help offers (default) |
  # | `:steal` | `RingTracer.Strategy.Steal` | an idle child steals half of a random sibling's atoms |
  #
  # A job names its strategy as `:name`, `{:name, options}` or `{module,
  # options}`; `resolve/2` turns any of them into `{module, options}` with the
  # strategy's own `RingTracer.Strategy.options/2`.

  alias RingTracer.{Error, Layout}

  @strategies %{
    static: RingTracer.Strategy.Static,
    master: RingTracer.Strategy.Master,
    ring: RingTracer.Strategy.Ring,
    steal: RingTracer.Strategy.Steal
  }

  @typedoc "A strategy as `render/2`'s `:strategy` option names it."
  @type given :: atom() | {atom(), keyword()}

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
  Whether `given` has the shape of a strategy (`:ring`, `{:ring, options}`,
  `{module, options}`): `:ok`, or what it must be.

      iex> RingTracer.Strategies.check({:ring, split: true})
      :ok
      iex> RingTracer.Strategies.check(:lottery)
      {:error, "one of [:static, :master, :ring, :steal], a name with its options ({:ring, split: true}) or {module, options} (see RingTracer.Strategy)"}
  """
  @spec check(term()) :: :ok | {:error, String.t()}
  def check(given) do
    case given do
      {m, o} when is_atom(m) and is_list(o) -> if Keyword.keyword?(o), do: :ok, else: shape()
      name when is_atom(name) -> if Map.has_key?(@strategies, name), do: :ok, else: shape()
      _ -> shape()
    end
  end

  defp shape,
    do:
      {:error,
       "one of #{inspect(names())}, a name with its options ({:ring, split: true}) " <>
         "or {module, options} (see RingTracer.Strategy)"}

  @doc """
  The strategy `given` (`render/2`'s `:strategy`) as a job's spec names it,
  `{module, options}`, its options checked and completed by the strategy
  itself (`RingTracer.Strategy.options/2`) for a job of layout `layout`.

      iex> layout = RingTracer.Layout.new(8, 1, 2, 2)
      iex> RingTracer.Strategies.resolve(:steal, layout)
      {:ok, {RingTracer.Strategy.Steal, []}}
      iex> {:ok, {RingTracer.Strategy.Ring, options}} = RingTracer.Strategies.resolve({:ring, split: true}, layout)
      iex> options[:split]
      true
      iex> {:error, error} = RingTracer.Strategies.resolve({:ring, hold_after: 0}, layout)
      iex> error.message
      "option :strategy: the ring's :hold_after must be a positive integer, got: 0"
  """
  @spec resolve(given() | RingTracer.Strategy.t(), Layout.t()) ::
          {:ok, RingTracer.Strategy.t()} | {:error, Error.t()}
  def resolve(given, %Layout{} = layout) do
    with :ok <- invalid(check(given)),
         {module, options} = module_of(given),
         :ok <- invalid(strategy?(module)) do
      case module.options(options, layout) do
        {:ok, options} -> {:ok, {module, options}}
        {:error, message} -> invalid({:error, message})
      end
    end
  end

  defp strategy?(module) do
    if Code.ensure_loaded?(module) and function_exported?(module, :options, 2),
      do: :ok,
      else: {:error, "#{inspect(module)} is not a RingTracer.Strategy"}
  end

  @doc """
  The name a result shows for the strategy `given`: its name, or its module
  for one given as `{module, options}`.

      iex> RingTracer.Strategies.name({:ring, aim: false})
      :ring
      iex> RingTracer.Strategies.name({MyStrategy, []})
      MyStrategy
  """
  @spec name(given() | RingTracer.Strategy.t()) :: atom()
  def name({name, _options}), do: name
  def name(name) when is_atom(name), do: name

  defp module_of({name, options}) do
    case module(name) do
      {:ok, module} -> {module, options}
      :error -> {name, options}
    end
  end

  defp module_of(name), do: module_of({name, []})

  defp invalid(:ok), do: :ok

  defp invalid({:error, message}),
    do: {:error, Error.new(:invalid_option, "option :strategy: #{message}")}
end
