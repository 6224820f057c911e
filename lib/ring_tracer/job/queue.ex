defmodule RingTracer.Job.Queue do
  @moduledoc false
  # A child's queue of atoms: taken from the front to be traced, given away
  # from the back. An Erlang `:queue` and its length, so that what a child
  # does once per atom (take the next one, tell its strategy how many are
  # queued and the share of the last) costs O(1), not O(queue): with a
  # list, a child of n atoms spent O(n^2) on them. Giving away `g` atoms
  # and queueing `m` received ones cost O(g) and O(m) (plus one pass over
  # the queue to drop atoms already held).

  alias RingTracer.Layout

  @enforce_keys [:q, :size]
  defstruct [:q, :size]

  @type t :: %__MODULE__{q: :queue.queue(Layout.atom_id()), size: non_neg_integer()}

  @spec new([Layout.atom_id()]) :: t()
  def new(atoms \\ []), do: %__MODULE__{q: :queue.from_list(atoms), size: length(atoms)}

  @spec size(t()) :: non_neg_integer()
  def size(%__MODULE__{size: n}), do: n

  @spec to_list(t()) :: [Layout.atom_id()]
  def to_list(%__MODULE__{q: q}), do: :queue.to_list(q)

  @doc "The next atom to trace and the rest, or `:empty`."
  @spec next(t()) :: {Layout.atom_id(), t()} | :empty
  def next(%__MODULE__{size: 0}), do: :empty

  def next(%__MODULE__{q: q, size: n}) do
    {{:value, a}, q} = :queue.out(q)
    {a, %__MODULE__{q: q, size: n - 1}}
  end

  @doc "The atom to be traced last, `nil` if none."
  @spec last(t()) :: Layout.atom_id() | nil
  def last(%__MODULE__{size: 0}), do: nil
  def last(%__MODULE__{q: q}), do: :queue.get_r(q)

  @doc "The queue with its last atom replaced by `a` (it must not be empty)."
  @spec replace_last(t(), Layout.atom_id()) :: t()
  def replace_last(%__MODULE__{q: q, size: n}, a) when n > 0,
    do: %__MODULE__{q: :queue.in(a, :queue.drop_r(q)), size: n}

  @doc "`a` to be traced next."
  @spec push_front(t(), Layout.atom_id()) :: t()
  def push_front(%__MODULE__{q: q, size: n}, a),
    do: %__MODULE__{q: :queue.in_r(a, q), size: n + 1}

  @doc "The last `g` atoms (all, if fewer), in queue order, and the queue without them."
  @spec take_last(t(), non_neg_integer()) :: {[Layout.atom_id()], t()}
  def take_last(%__MODULE__{q: q, size: n}, g) do
    {give, q} = take_r(q, min(g, n), [])
    {give, %__MODULE__{q: q, size: n - min(g, n)}}
  end

  defp take_r(q, 0, acc), do: {acc, q}

  defp take_r(q, k, acc) do
    {{:value, a}, q} = :queue.out_r(q)
    take_r(q, k - 1, [a | acc])
  end

  @doc "Appends the `atoms` that are neither in `held` (a set) nor queued already; returns them too."
  @spec append(t(), [Layout.atom_id()], MapSet.t()) :: {t(), [Layout.atom_id()]}
  def append(%__MODULE__{q: q, size: n}, atoms, held) do
    incoming = MapSet.new(atoms)
    queued = MapSet.new(Enum.filter(:queue.to_list(q), &MapSet.member?(incoming, &1)))
    new = Enum.reject(atoms, &(MapSet.member?(held, &1) or MapSet.member?(queued, &1)))
    {%__MODULE__{q: :queue.join(q, :queue.from_list(new)), size: n + length(new)}, new}
  end
end
