defmodule RingTracer.Job.Ledger do
  @moduledoc false
  # Where the parent believes each atom may be, so that when a child dies it
  # can hand out again, at once, exactly the atoms that died with it.
  #
  # Every child starts with its strategy's initial atoms. After that an atom
  # moves only by a hand-over, and whoever moves it tells the parent: a
  # child that gives atoms to a sibling sends the hand-over first and then
  # `{:gave, from, to, atoms}` to the parent; the parent records its own
  # hand-outs as it sends them. Reports from different children can arrive
  # in any order (a sibling may report passing an atom on before the report
  # of it receiving it arrives), so the ledger keeps counts, not places: per
  # child and atom, one for each time it was given the atom and minus one
  # for each time it gave it away. A child may hold an atom if its count is
  # positive; once every report has arrived, exactly one child has a
  # positive count.
  #
  # When a child dies the parent hands out again every atom the child may
  # hold and that has not been traced. Because a child reports after it has
  # sent the hand-over, a child that dies between the two leaves its atoms
  # on its own account: they are handed out again and traced twice, never
  # lost. A report of atoms given to a child already dead hands them out
  # again too. Counting what may be held, not what is, errs only towards
  # tracing an atom twice (the parent keeps the first copy).
  #
  # A hand-over can also be lost on its way: when the giver's node freezes
  # or drops with the message still in its buffers towards a third node,
  # while its report, on another connection, reached the parent. So the
  # receiver confirms what it got (`{:got, from, to, atoms}`), and atoms a
  # child gave that no receiver has confirmed yet are *in transit*: when the
  # giver dies they are handed out again too (`in_transit/2`), as its own
  # are.

  alias RingTracer.Layout

  @enforce_keys [:layout, :strategy]
  defstruct [:layout, :strategy, moves: %{}, unconfirmed: %{}]

  @typedoc "Per child, the atoms whose count differs from the initial one, by how much."
  @type t :: %__MODULE__{
          layout: Layout.t(),
          strategy: RingTracer.Strategy.t(),
          moves: %{non_neg_integer() => %{Layout.atom_id() => integer()}},
          unconfirmed: %{non_neg_integer() => %{Layout.atom_id() => integer()}}
        }

  @doc """
  A ledger where each child holds its strategy's initial atoms (the
  strategy as `{module, options}`, or a module with no options).

      iex> layout = RingTracer.Layout.new(8, 8, 2, 2)
      iex> ledger = RingTracer.Job.Ledger.new(layout, RingTracer.Strategy.Ring)
      iex> RingTracer.Job.Ledger.held(ledger, 1)
      [2, 3]
  """
  @spec new(Layout.t(), RingTracer.Strategy.t() | module()) :: t()
  def new(layout, {module, options}) when is_atom(module) and is_list(options),
    do: %__MODULE__{layout: layout, strategy: {module, options}}

  def new(layout, module) when is_atom(module), do: new(layout, {module, []})

  @doc """
  `atoms` moved from child `from` (or `:parent`) to child `to` (or
  `:nobody`, for a child already dead).

      iex> layout = RingTracer.Layout.new(8, 8, 3, 2)
      iex> l = RingTracer.Job.Ledger.new(layout, RingTracer.Strategy.Ring)
      iex> # Child 1 reports giving atom 3 to child 2 before child 0's report
      iex> # of giving it to child 1 arrives: for a moment 0 and 2 may hold it.
      iex> l = RingTracer.Job.Ledger.moved(l, 1, 2, [1])
      iex> {RingTracer.Job.Ledger.held(l, 0), RingTracer.Job.Ledger.held(l, 2)}
      {[0, 1], [1, 4, 5]}
      iex> l = RingTracer.Job.Ledger.moved(l, 0, 1, [1])
      iex> {RingTracer.Job.Ledger.held(l, 0), RingTracer.Job.Ledger.held(l, 1), RingTracer.Job.Ledger.held(l, 2)}
      {[0], [2, 3], [1, 4, 5]}
  """
  @spec moved(t(), non_neg_integer() | :parent, non_neg_integer() | :nobody, [Layout.atom_id()]) ::
          t()
  def moved(ledger, from, to, atoms) do
    ledger = ledger |> add(from, atoms, -1) |> add(to, atoms, 1)

    if is_integer(from) and is_integer(to),
      do: count(ledger, :unconfirmed, from, atoms, 1),
      else: ledger
  end

  @doc """
  Child `to` confirms it received `atoms` from child `from`: they are no
  longer in transit. A confirmation may come before the giver's report.

      iex> layout = RingTracer.Layout.new(8, 8, 3, 2)
      iex> l = RingTracer.Job.Ledger.new(layout, RingTracer.Strategy.Ring)
      iex> l = RingTracer.Job.Ledger.moved(l, 0, 2, [1])
      iex> RingTracer.Job.Ledger.in_transit(l, 0)
      [1]
      iex> RingTracer.Job.Ledger.in_transit(RingTracer.Job.Ledger.received(l, 0, [1]), 0)
      []
      iex> early = RingTracer.Job.Ledger.received(RingTracer.Job.Ledger.new(layout, RingTracer.Strategy.Ring), 0, [1])
      iex> RingTracer.Job.Ledger.in_transit(RingTracer.Job.Ledger.moved(early, 0, 2, [1]), 0)
      []
  """
  @spec received(t(), non_neg_integer(), [Layout.atom_id()]) :: t()
  def received(ledger, from, atoms), do: count(ledger, :unconfirmed, from, atoms, -1)

  @doc """
  The atoms child `index` gave that no receiver has confirmed yet: lost
  with it if its node went down with the hand-over still in its buffers.
  """
  @spec in_transit(t(), non_neg_integer()) :: [Layout.atom_id()]
  def in_transit(ledger, index) do
    for {a, n} <- Map.get(ledger.unconfirmed, index, %{}), n > 0, do: a
  end

  defp add(ledger, who, _atoms, _d) when who in [:parent, :nobody], do: ledger
  defp add(ledger, who, atoms, d), do: count(ledger, :moves, who, atoms, d)

  # Adds `d` to `who`'s count of each atom in the ledger's `key` map,
  # dropping counts that come back to zero.
  defp count(ledger, key, who, atoms, d) do
    mine =
      Enum.reduce(atoms, Map.get(Map.fetch!(ledger, key), who, %{}), fn a, acc ->
        case Map.get(acc, a, 0) + d do
          0 -> Map.delete(acc, a)
          n -> Map.put(acc, a, n)
        end
      end)

    Map.put(ledger, key, Map.put(Map.fetch!(ledger, key), who, mine))
  end

  @doc """
  The atoms child `index` may hold (traced ones included), in order. A
  child that joined the running job (an index beyond the layout's
  children) started with none.
  """
  @spec held(t(), non_neg_integer()) :: [Layout.atom_id()]
  def held(ledger, index) do
    initial = MapSet.new(initial_atoms(ledger, index))
    moves = Map.get(ledger.moves, index, %{})

    initial
    |> MapSet.union(MapSet.new(Map.keys(moves)))
    |> Enum.filter(fn a ->
      if(MapSet.member?(initial, a), do: 1, else: 0) + Map.get(moves, a, 0) > 0
    end)
    |> Enum.sort()
  end

  @doc """
  The atoms child `index` holds at the start: its strategy's initial atoms,
  none for a child that joined the running job (`RingTracer.grow/4`).
  """
  @spec initial_atoms(t() | {Layout.t(), RingTracer.Strategy.t()}, non_neg_integer()) ::
          [Layout.atom_id()]
  def initial_atoms(%__MODULE__{layout: layout, strategy: strategy}, index),
    do: initial_atoms({layout, strategy}, index)

  def initial_atoms({%Layout{children: n}, _strategy}, index) when index >= n, do: []

  def initial_atoms({layout, {strategy, options}}, index),
    do: strategy.initial_atoms(layout, index, options)

  @doc """
  Forgets the moves of the atoms in `atoms` (a frame's, once it is
  complete: `RingTracer.Layout`, "Frames"), pieces included, so that the
  ledger holds the frames in flight only. A child may then seem to hold
  initial atoms of that frame again; they are traced, and the parent never
  hands them out again.

      iex> layout = RingTracer.Layout.new(8, 8, 2, 2) |> RingTracer.Layout.with_frames(2)
      iex> l = RingTracer.Job.Ledger.new(layout, RingTracer.Strategy.Ring)
      iex> l = RingTracer.Job.Ledger.moved(l, :parent, 1, [6, 7, {4, 1, 2, 2}])
      iex> RingTracer.Job.Ledger.held(RingTracer.Job.Ledger.drop(l, 4..7), 1)
      [2, 3]
  """
  @spec drop(t(), Range.t()) :: t()
  def drop(ledger, atoms) do
    forget_atoms = fn by ->
      Map.new(by, fn {who, mine} ->
        {who, Map.reject(mine, fn {a, _} -> Layout.base(a) in atoms end)}
      end)
    end

    %{ledger | moves: forget_atoms.(ledger.moves), unconfirmed: forget_atoms.(ledger.unconfirmed)}
  end

  @doc """
  Forgets child `index`'s moves and what it gave in transit (it is dead
  and those atoms handed out again; moves to it are recorded as to
  `:nobody` from now on).
  """
  @spec forget(t(), non_neg_integer()) :: t()
  def forget(ledger, index),
    do: %{
      ledger
      | moves: Map.delete(ledger.moves, index),
        unconfirmed: Map.delete(ledger.unconfirmed, index)
    }
end
