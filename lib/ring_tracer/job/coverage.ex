defmodule RingTracer.Job.Coverage do
  @moduledoc false
  # Which parts of each atom the parent holds, as atoms may arrive whole or in
  # pieces (`RingTracer.Layout`, "Pieces"), and after a failure twice or in
  # overlapping pieces. Per atom: the union of the shares received, as
  # disjoint intervals of `[0, 1]` with rational ends.

  alias RingTracer.Layout

  @typedoc "A rational, `{numerator, denominator}`, reduced."
  @type q :: {non_neg_integer(), pos_integer()}

  @typedoc "Per atom, the disjoint intervals received, in order."
  @type t :: %{non_neg_integer() => [{q(), q()}]}

  @doc "Nothing received."
  @spec new() :: t()
  def new, do: %{}

  @doc """
  Adds atom or piece `a`: `:new` if it covers anything not covered yet,
  `:duplicate` (and the coverage unchanged) otherwise.

      iex> alias RingTracer.Job.Coverage
      iex> {:new, c} = Coverage.add(Coverage.new(), {3, 0, 1, 2})
      iex> Coverage.complete?(c, 3)
      false
      iex> {:duplicate, ^c} = Coverage.add(c, {3, 1, 2, 4})
      iex> {:new, c} = Coverage.add(c, {3, 1, 2, 2})
      iex> {Coverage.complete?(c, 3), Coverage.covered?(c, 3)}
      {true, true}
      iex> Coverage.add(c, 3) |> elem(0)
      :duplicate
  """
  @spec add(t(), Layout.atom_id()) :: {:new | :duplicate, t()}
  def add(coverage, a) do
    {lo, hi} = interval(a)
    union = Map.get(coverage, Layout.base(a), [])

    if contains?(union, lo, hi),
      do: {:duplicate, coverage},
      else: {:new, Map.put(coverage, Layout.base(a), merge(union, {lo, hi}))}
  end

  @doc "Whether every part of atom or piece `a` has been received."
  @spec covered?(t(), Layout.atom_id()) :: boolean()
  def covered?(coverage, a) do
    {lo, hi} = interval(a)
    contains?(Map.get(coverage, Layout.base(a), []), lo, hi)
  end

  @doc "Whether all of atom `a` has been received."
  @spec complete?(t(), non_neg_integer()) :: boolean()
  def complete?(coverage, a), do: covered?(coverage, a)

  @doc """
  Whether `ids` (atoms and pieces) tile every atom of `layout` exactly once:
  together they cover each atom, and their shares add up to one atom.

      iex> layout = RingTracer.Layout.new(4, 1, 1, 2)
      iex> RingTracer.Job.Coverage.tiles?(layout, [0, {1, 0, 1, 2}, {1, 1, 2, 2}])
      true
      iex> RingTracer.Job.Coverage.tiles?(layout, [0, {1, 0, 1, 2}, {1, 1, 3, 4}, 1])
      false
      iex> RingTracer.Job.Coverage.tiles?(layout, [0])
      false
  """
  @spec tiles?(Layout.t(), [Layout.atom_id()]) :: boolean()
  def tiles?(layout, ids) do
    coverage = Enum.reduce(ids, new(), &elem(add(&2, &1), 1))

    shares =
      Enum.group_by(ids, &Layout.base/1, &Layout.fraction/1)
      |> Map.new(fn {a, fs} ->
        {a, Enum.reduce(fs, {0, 1}, fn {k, d}, {n, m} -> q(n * d + k * m, m * d) end)}
      end)

    map_size(shares) == Layout.atom_count(layout) and
      Enum.all?(Layout.atoms(layout), &(complete?(coverage, &1) and shares[&1] == {1, 1}))
  end

  defp interval(a) do
    case a do
      {_, lo, hi, d} -> {q(lo, d), q(hi, d)}
      _ -> {{0, 1}, {1, 1}}
    end
  end

  defp q(n, d) do
    g = Integer.gcd(n, d)
    {div(n, g), div(d, g)}
  end

  defp le({a, b}, {c, d}), do: a * d <= c * b

  # The union is merged (touching intervals are one), so a covered interval
  # lies in one of them.
  defp contains?(union, lo, hi), do: Enum.any?(union, fn {l, h} -> le(l, lo) and le(hi, h) end)

  defp merge(union, interval) do
    [interval | union]
    |> Enum.sort(fn {l1, _}, {l2, _} -> le(l1, l2) end)
    |> Enum.reduce([], fn
      {l, h}, [{pl, ph} | rest] ->
        if le(l, ph),
          do: [{pl, if(le(h, ph), do: ph, else: h)} | rest],
          else: [{l, h}, {pl, ph} | rest]

      iv, [] ->
        [iv]
    end)
    |> Enum.reverse()
  end
end
