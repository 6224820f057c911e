defmodule RingTracer.Rays do
  @moduledoc false
  # Ray counters, of an atom, a child or a job: a map of non-negative
  # integers under the kernel's own names (`RayStats` in
  # `native/kernel/src/stats.rs`, which the NIF reports when this module
  # compiles), the rays of each kind and the kernel's work units.

  @external_resource "native/kernel/src/stats.rs"
  {zero, kinds} = RingTracer.Native.ray_counters()
  @zero zero
  @kinds kinds

  @typedoc "Counters by name (`zero/0`'s keys)."
  @type t :: %{required(atom()) => non_neg_integer()}

  @doc "Every counter at zero."
  @spec zero() :: t()
  def zero, do: @zero

  @doc """
  The counters that count rays (eye hits and work units do not).

      iex> Map.keys(RingTracer.Rays.zero())
      [:eye, :eye_hits, :reflected, :refracted, :shadow, :work]
      iex> RingTracer.Rays.kinds()
      [:eye, :reflected, :refracted, :shadow]
  """
  @spec kinds() :: [atom()]
  def kinds, do: @kinds

  @doc """
  The sum of two sets of counters.

      iex> a = %{RingTracer.Rays.zero() | eye: 2, work: 10}
      iex> RingTracer.Rays.add(a, %{a | shadow: 1}) |> Map.take([:eye, :shadow, :work])
      %{eye: 4, shadow: 1, work: 20}
  """
  @spec add(t(), t()) :: t()
  # Written out key by key at compile time: a child adds an atom's counters
  # to its own for every atom, and a generic merge cost several times more.
  var = fn prefix, key -> Macro.var(:"#{prefix}_#{key}", __MODULE__) end
  keys = Map.keys(zero)

  def add(%{unquote_splicing(Enum.map(keys, &{&1, var.(:a, &1)}))}, %{
        unquote_splicing(Enum.map(keys, &{&1, var.(:b, &1)}))
      }) do
    %{
      unquote_splicing(
        Enum.map(keys, &{&1, quote(do: unquote(var.(:a, &1)) + unquote(var.(:b, &1)))})
      )
    }
  end

  @doc """
  All rays traced, of every kind.

      iex> RingTracer.Rays.total(%{RingTracer.Rays.zero() | eye: 4, eye_hits: 3, shadow: 2, work: 90})
      6
  """
  @spec total(t()) :: non_neg_integer()
  def total(%{unquote_splicing(Enum.map(kinds, &{&1, var.(:n, &1)}))}) do
    unquote(
      kinds
      |> Enum.map(&var.(:n, &1))
      |> Enum.reduce(&quote(do: unquote(&2) + unquote(&1)))
    )
  end
end
