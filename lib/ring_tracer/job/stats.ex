defmodule RingTracer.Job.Stats do
  @moduledoc false
  # A child's statistics: the one list of them, which the child counts
  # (`RingTracer.Job.Child`), the result reports (`RingTracer.Result`'s
  # `:children`) and the reports' tables show (`columns/0`:
  # `RingTracer.Report.Stats`, `RingTracer.Preview.Log`,
  # `RingTracer.CLI.Report`). The counters strategies move with `{:stat, key}`
  # are `RingTracer.Strategy.stats/0`.

  # Every field with its default, in a table's order; the strategies'
  # counters are `RingTracer.Strategy.stats/0`'s.
  @fields [index: nil, node: nil, speed: nil, own: nil] ++
            [given: 0, received: 0, splits: 0, cuts: 0, handovers: 0, traced: 0] ++
            Enum.map(RingTracer.Strategy.stats(), &{&1, 0}) ++
            [grandchild_restarts: 0, busy_us: 0, trace_us: 0, idle_us: nil] ++
            [first_atom_us: nil, last_atom_us: nil, rays: %{}, failed: nil]

  @enforce_keys [:index, :node, :speed, :own]
  defstruct @fields

  @typedoc """
  A child's statistics: `:index`, `:node`, `:speed` (its slowdown factor),
  atoms `:own`, `:given`, `:received`, `:splits` (atoms it cut in two to
  give part of one: adaptive atoms, one item more each, so `traced == own -
  given + received + splits`), `:cuts` (of those, cuts of the atom being
  traced, `RingTracer.Job.Pipe.cut/3`), `:handovers` (hand-over messages
  received), `:traced` (atoms and pieces), the strategy's counters
  (`RingTracer.Strategy.stats/0`: offers `:offers_sent`, `:offers_passed`,
  offer messages passed on together counting once, `:offers_consumed`; for
  `:steal`, requests sent, refused and granted), `:grandchild_restarts`,
  `:busy_us` (wall time its grandchild spent on atoms, slowdown included),
  `:trace_us` (kernel time), `:idle_us` (set once the job's makespan is
  known), `:first_atom_us` and `:last_atom_us` (from the job's start),
  `:rays` (its ray counters and work units: `rays.work / busy_us` is its
  speed), `:failed` (why, for a child that died mid-job: its counts are
  zero).
  """
  @type t :: %__MODULE__{
          index: non_neg_integer(),
          node: node() | nil,
          speed: number(),
          own: non_neg_integer(),
          given: non_neg_integer(),
          received: non_neg_integer(),
          splits: non_neg_integer(),
          cuts: non_neg_integer(),
          handovers: non_neg_integer(),
          traced: non_neg_integer(),
          offers_sent: non_neg_integer(),
          offers_passed: non_neg_integer(),
          offers_consumed: non_neg_integer(),
          grandchild_restarts: non_neg_integer(),
          busy_us: non_neg_integer(),
          trace_us: non_neg_integer(),
          idle_us: non_neg_integer() | nil,
          first_atom_us: integer() | nil,
          last_atom_us: integer() | nil,
          rays: map(),
          failed: String.t() | nil
        }

  @doc """
  A child's statistics before its first atom (also what a dead child
  reports): child `index` on `node`, of slowdown `speed`, owning `own` atoms.
  """
  @spec new(non_neg_integer(), node() | nil, number(), non_neg_integer()) :: t()
  def new(index, node, speed, own),
    do: %__MODULE__{
      index: index,
      node: node,
      speed: speed,
      own: own,
      rays: RingTracer.Kernel.no_rays()
    }

  @doc """
  The statistics a table shows, one column each, in order: every field but
  the ray counters (columns of their own) and `:failed`.

      iex> RingTracer.Job.Stats.columns() |> Enum.take(4)
      [:index, :node, :speed, :own]
      iex> Enum.all?(RingTracer.Strategy.stats(), &(&1 in RingTracer.Job.Stats.columns()))
      true
  """
  @spec columns() :: [atom()]
  def columns, do: Keyword.keys(@fields) -- [:rays, :failed]

  @doc """
  A child's speed: kernel work units traced (its `:rays` counters'
  `:work`) per microsecond its grandchild spent on atoms (wall time,
  slowdown included); `nil` until it has traced work. Unlike a count of
  atoms, it does not take a child that traced cheap atoms for a fast one.

      iex> stats = RingTracer.Job.Stats.new(0, node(), 1, 4)
      iex> RingTracer.Job.Stats.rate(stats)
      nil
      iex> RingTracer.Job.Stats.rate(%{stats | busy_us: 2_000, rays: %{stats.rays | work: 5_000}})
      2.5
  """
  @spec rate(t()) :: float() | nil
  def rate(%__MODULE__{rays: %{work: work}, busy_us: busy}) when work > 0 and busy > 0,
    do: work / busy

  def rate(%__MODULE__{}), do: nil

  @doc """
  A child's mean wall time per atom (slowdown included), `nil` before its
  first atom.

      iex> RingTracer.Job.Stats.mean_atom_us(%{RingTracer.Job.Stats.new(0, node(), 1, 4) | traced: 4, busy_us: 100})
      25
  """
  @spec mean_atom_us(t()) :: non_neg_integer() | nil
  def mean_atom_us(%__MODULE__{traced: 0}), do: nil
  def mean_atom_us(%__MODULE__{busy_us: busy, traced: n}), do: div(busy, n)
end
