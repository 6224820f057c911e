defmodule RingTracer.Job.Slowdown do
  @moduledoc false
  # How a child of speed factor `s > 1` emulates a machine `s` times slower:
  # after each atom it waits `(s - 1)` times the atom's trace time, without
  # burning CPU.
  #
  # BEAM timers have millisecond resolution and fire late when the cores are
  # busy: the process must wait for a scheduler thread, which competes with
  # the dirty schedulers tracing other atoms. On this project's 2-core machine
  # with 8 children tracing, a sleep ran 1.4-2.4 ms late on average, so a
  # child of speed 2 waited 53% longer than it should and the emulated
  # machines were slower than their factors. So the wait keeps a balance:
  # each atom adds `(s - 1) x trace` to it, each sleep takes off what it
  # actually lasted (late included), and the next sleep is shortened by what
  # the last overran. Over a job a child waits what its factor says, within
  # one sleep's error.

  @enforce_keys [:speed]
  defstruct [:speed, balance: 0]

  # A slowdown beyond this emulates no machine anyone renders on, and its
  # sleeps would overflow timers.
  @max 1000

  @doc """
  The largest slowdown factor a child or a node may have (the smallest is 1).

      iex> RingTracer.Job.Slowdown.max()
      1000
  """
  @spec max() :: pos_integer()
  def max, do: @max

  @doc """
  Whether `factor` is a slowdown factor (a number from 1 to `max/0`).

      iex> RingTracer.Job.Slowdown.factor?(4)
      true
      iex> RingTracer.Job.Slowdown.factor?(0.5)
      false
  """
  @spec factor?(term()) :: boolean()
  def factor?(factor), do: is_number(factor) and factor >= 1 and factor <= @max

  @typedoc """
  A child's speed factor and its wait balance in microseconds (negative when
  past sleeps overran).
  """
  @type t :: %__MODULE__{speed: number(), balance: integer()}

  @doc """
  This node's own speed factor, multiplied into the job's for every child
  it hosts: 1 unless the node was started to emulate a slower machine
  (a farm worker's `:speed`, `RingTracer.Farm.join/2`, for benchmarks and
  soaks), which sets the application environment's `:node_speed`.
  """
  @spec node_speed() :: number()
  def node_speed, do: Application.get_env(:ring_tracer, :node_speed, 1)

  @doc "No wait owed yet, for speed factor `speed`."
  @spec new(number()) :: t()
  def new(speed) when is_number(speed), do: %__MODULE__{speed: speed}

  @doc """
  Microseconds to wait after an atom traced in `trace_us`.

      iex> alias RingTracer.Job.Slowdown
      iex> Slowdown.owed(Slowdown.new(1), 5_000)
      0
      iex> Slowdown.owed(Slowdown.new(3), 5_000)
      10_000
      iex> Slowdown.owed(%{Slowdown.new(3) | balance: -1_500}, 5_000)
      8_500
  """
  @spec owed(t(), non_neg_integer()) :: integer()
  def owed(%__MODULE__{speed: speed}, _trace_us) when speed <= 1, do: 0

  def owed(%__MODULE__{speed: speed, balance: balance}, trace_us),
    do: balance + round((speed - 1) * trace_us)

  @doc """
  What to do after an atom traced in `trace_us`: `{sleep_ms, owed_us}`,
  milliseconds to sleep (0: none, what is owed is under half a
  millisecond) and microseconds owed in all.

      iex> alias RingTracer.Job.Slowdown
      iex> Slowdown.plan(Slowdown.new(1), 50_000)
      {0, 0}
      iex> Slowdown.plan(%{Slowdown.new(4) | balance: -2_000}, 1_000)
      {1, 1_000}
  """
  @spec plan(t(), non_neg_integer()) :: {non_neg_integer(), integer()}
  def plan(%__MODULE__{} = slowdown, trace_us) do
    owed = owed(slowdown, trace_us)
    if owed >= 500, do: {div(owed + 500, 1000), owed}, else: {0, owed}
  end

  @doc "The balance once `slept_us` of what was `owed_us` have passed (late timers included)."
  @spec settle(t(), integer(), non_neg_integer()) :: t()
  def settle(%__MODULE__{} = slowdown, owed_us, slept_us),
    do: %{slowdown | balance: owed_us - slept_us}

  @doc """
  Waits after an atom traced in `trace_us` and returns the new balance. A
  child of speed 1 returns at once.
  """
  @spec wait(t(), non_neg_integer()) :: t()
  def wait(%__MODULE__{} = slowdown, trace_us) do
    case plan(slowdown, trace_us) do
      {0, owed} ->
        settle(slowdown, owed, 0)

      {ms, owed} ->
        t0 = System.monotonic_time(:microsecond)
        Process.sleep(ms)
        settle(slowdown, owed, System.monotonic_time(:microsecond) - t0)
    end
  end
end
