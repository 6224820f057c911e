defmodule RingTracer.Rays do
  @moduledoc """
  Ray counters, of an atom, a child or a job: a map of non-negative
  integers under the kernel's own names (`RayStats` in
  `native/kernel/src/stats.rs`, which the NIF reports when this module
  compiles), the rays of each kind and the kernel's work units.

      iex> Map.keys(RingTracer.Rays.zero())
      [:eye, :eye_hits, :reflected, :refracted, :shadow, :work]
      iex> RingTracer.Rays.kinds()
      [:eye, :reflected, :refracted, :shadow]
  """

  @external_resource "native/kernel/src/stats.rs"
  {zero, kinds} = RingTracer.Native.ray_counters()
  @zero zero
  @kinds kinds

  @typedoc "Counters by name (`zero/0`'s keys)."
  @type t :: %{required(atom()) => non_neg_integer()}

  @doc "Every counter at zero."
  @spec zero() :: t()
  def zero, do: @zero

  @doc "The counters that count rays (eye hits and work units do not)."
  @spec kinds() :: [atom()]
  def kinds, do: @kinds

  @doc """
  The sum of two sets of counters.

      iex> a = %{RingTracer.Rays.zero() | eye: 2, work: 10}
      iex> RingTracer.Rays.add(a, %{a | shadow: 1}) |> Map.take([:eye, :shadow, :work])
      %{eye: 4, shadow: 1, work: 20}
  """
  @spec add(t(), t()) :: t()
  def add(a, b), do: Map.merge(a, b, fn _, x, y -> x + y end)

  @doc """
  All rays traced, of every kind.

      iex> RingTracer.Rays.total(%{RingTracer.Rays.zero() | eye: 4, eye_hits: 3, shadow: 2, work: 90})
      6
  """
  @spec total(t()) :: non_neg_integer()
  def total(rays), do: Enum.reduce(@kinds, 0, &(Map.fetch!(rays, &1) + &2))
end
