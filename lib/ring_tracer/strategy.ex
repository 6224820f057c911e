defmodule RingTracer.Strategy do
  @moduledoc """
  A load-balancing strategy: a pure policy that decides what a child does
  when it runs out of atoms, and what it does with strategy messages from its
  siblings or its parent.

  Every strategy works on the same atoms, with the same kernel, and gives
  byte-identical images; they differ in who traces which atom, when, and
  how many messages that costs (`RingTracer.Strategies` lists them).

  ## The seam

  A callback gets a read-only view of its process (`RingTracer.Strategy.View`
  in a child, `RingTracer.Strategy.ParentView` in the parent) and the
  strategy's own state, and returns the new state and a list of effects.
  The process carries the effects out, in order, in one place: it sends and
  counts the messages, takes atoms out of its queue, records the events.
  A strategy never sees a process's state and never sends a message itself.

  A strategy is named in a job's spec as `{module, options}`, like a kernel;
  its options are its own (the ring's `:hold_after`, `:aim` and `:split`):
  `options/2` checks them and fills in their defaults before the job starts.

  `use RingTracer.Strategy` declares the behaviour and gives every callback a
  default, so that a strategy defines only what it changes: see
  [docs/strategies.md](strategies.md) for a walk-through.
  """

  alias RingTracer.Layout
  alias RingTracer.Strategy.{ParentView, View}

  @typedoc "A strategy as a job's spec names it."
  @type t :: {module(), options()}

  @typedoc "A strategy's own options."
  @type options :: keyword()

  @typedoc "A strategy's own state, in a child or in the parent."
  @type state :: term()

  @typedoc "Who a child's message goes to: a pid, a sibling by index, or the parent."
  @type to :: pid() | {:sibling, non_neg_integer()} | :parent

  @typedoc "The kinds of message a strategy sends, as the job's statistics count them."
  @type kind :: :offer | :control

  # The child's counters that only strategies move (`{:stat, key}`): written
  # here alone, read by the type below, `is_stat/1` and `RingTracer.Job.Stats`.
  @stats [:offers_sent, :offers_passed, :offers_consumed]

  @typedoc "A child's counters that only strategies move (`stats/0`)."
  @type stat :: unquote(Enum.reduce(Enum.reverse(@stats), &{:|, [], [&1, &2]}))

  @typedoc """
  What a child's callback asks of its child, carried out in order:

    * `{:send, to, kind, message}` — sends `message`, counted under `kind`;
    * `{:give, pid, index, n}` — takes up to `n` atoms, farthest from being
      traced first, and hands them over to sibling `index` at `pid`
      (possibly none: a refusal); the hand-over carries `handover_news/2`;
    * `{:give, pid, index, n, {k, d}}` — the same, and with the `n` atoms
      the last `k` of `d` parts of the next one (`RingTracer.Layout.split/3`:
      its first parts stay with the child);
    * `{:cut, pid, index, keep}` — cuts the atom being traced, where its
      grandchild traces it in parts (`parts/2`, `RingTracer.Job.Pipe.cut/3`):
      of the parts not yet started, the first `keep` share (0.0 to 1.0,
      rounded down in parts) is queued again, the rest is handed over as
      with `:give` (nothing, when every part has started: a refusal);
    * `{:queue, atoms}` — queues atoms handed over to the child, which
      starts on them (and, holding nothing new, is idle again);
    * `{:left, pid, index}` — the child's left sibling is now `index`;
    * `:finished` — the child has nothing more to do until the job stops;
    * `{:event, kind, to}` — records a protocol event for the timeline;
    * `{:stat, stat}` — adds one to one of the child's counters;
    * `{:continue, message}` — once the effects before it are carried out,
      calls `handle_message/3` with `message` and a fresh view (for
      decisions that depend on what those effects did to the queue).
  """
  @type effect ::
          {:send, to(), kind(), term()}
          | {:give, pid(), non_neg_integer(), non_neg_integer()}
          | {:give, pid(), non_neg_integer(), non_neg_integer(), part() | nil}
          | {:cut, pid(), non_neg_integer(), float()}
          | {:queue, [Layout.atom_id()]}
          | {:left, pid(), non_neg_integer()}
          | :finished
          | {:event, atom(), term()}
          | {:stat, stat()}
          | {:continue, term()}

  @typedoc """
  What a parent's callback asks of the parent, carried out in order:

    * `{:send, index, kind, message}` — sends `message` to child `index`;
    * `{:hand_out, index, atoms}` — hands atoms to child `index`, recorded in
      the job's `RingTracer.Job.Ledger`;
    * `{:helper, tag, {module, function, args}}` — applies `function` in a
      process of the job's, which the parent ends and waits for when the job
      ends; its value comes back to the strategy as the message
      `{tag, value}` (`parent_info/3`).
  """
  @type parent_effect ::
          {:send, non_neg_integer(), kind(), term()}
          | {:hand_out, non_neg_integer(), [Layout.atom_id()]}
          | {:helper, term(), {module(), atom(), [term()]}}

  @typedoc "`{k, d}`: `k` of `d` equal parts of an atom or piece, `0 < k < d`."
  @type part :: {pos_integer(), pos_integer()}

  @typedoc "A callback's answer: the strategy's new state and what to do."
  @type result(effect) :: {state(), [effect]}

  @doc """
  The strategy's options as given (`strategy: {name_or_module, options}`),
  checked, with its defaults filled in, for a job of layout `layout` (its
  order and frames are known, its children and atoms): `{:error, message}`
  names what is wrong, and the job does not start. Pure. Default: the
  options as given.
  """
  @callback options(options(), Layout.t()) :: {:ok, options()} | {:error, String.t()}

  @doc "The atoms a child holds at the start (default: its strip)."
  @callback initial_atoms(Layout.t(), index :: non_neg_integer(), options()) :: [Layout.atom_id()]

  @doc "A child's strategy state at the start (default: `%{}`)."
  @callback init(options()) :: state()

  @doc """
  In how many parts (kernel calls) the grandchild traces the atom the child
  puts in its pipe now; parts not yet started can be cut off (`{:cut, ...}`).
  Default: 1, whole.
  """
  @callback parts(View.t(), state()) :: pos_integer()

  @doc "The child has nothing queued and nothing in its grandchild's pipe."
  @callback idle(View.t(), state()) :: result(effect())

  @doc """
  A message the child does not know itself, or one of the child's news:
  `{:siblings_died, dead}` once the parent has re-linked the ring around
  dead siblings, `{:siblings_joined, joined}` once siblings joined a
  running job (the view's `ring_size` counts them). Default: atoms handed
  over are queued, anything else is ignored.
  """
  @callback handle_message(term(), View.t(), state()) :: result(effect())

  @doc """
  What a hand-over the child makes carries besides its atoms (`nil`:
  nothing), from the view after the atoms left. Default: nothing.
  """
  @callback handover_news(View.t(), state()) :: {term(), state()}

  @doc "The parent, once the children are linked; returns the parent's strategy state."
  @callback parent_start(ParentView.t(), options()) :: result(parent_effect())

  @doc "The parent, each time a new atom arrives from child `index`."
  @callback parent_atom_done(ParentView.t(), state(), index :: non_neg_integer()) ::
              result(parent_effect())

  @doc """
  The parent, when frame `frame` (from 0) of a job of several frames is
  released (`RingTracer.Layout`, "Frames"): the first frame is the initial
  atoms', each later one comes when a frame completes and leaves room in
  the job's window. Default: each child gets its strip of the frame (the
  strip of a child that died is spread over the living).
  """
  @callback parent_frame(ParentView.t(), state(), frame :: pos_integer()) ::
              result(parent_effect())

  @doc """
  The parent, once children `joined` (indices from the view's `size`
  before the join) have joined the running job (`RingTracer.grow/4`): they
  are linked into the ring and hold no atoms; each is told `idle/2` as it
  starts, and finds work through its strategy. Default: nothing (the ring
  and steal find work through their siblings, static has none to find;
  master hands them atoms here).
  """
  @callback parent_joined(ParentView.t(), state(), joined :: [non_neg_integer()]) ::
              result(parent_effect())

  @doc """
  The parent, on a message it does not know itself (for instance the reply
  of a helper the strategy started in `parent_start/2`).
  """
  @callback parent_info(term(), ParentView.t(), state()) :: result(parent_effect())

  defmacro __using__(_opts) do
    quote do
      @behaviour RingTracer.Strategy

      @impl RingTracer.Strategy
      def options(options, _layout), do: {:ok, options}

      @impl RingTracer.Strategy
      def initial_atoms(layout, index, _options), do: RingTracer.Layout.strip(layout, index)

      @impl RingTracer.Strategy
      def init(_options), do: %{}

      @impl RingTracer.Strategy
      def parts(_view, _state), do: 1

      @impl RingTracer.Strategy
      def handle_message(message, view, state),
        do: RingTracer.Strategy.default_message(message, view, state)

      @impl RingTracer.Strategy
      def handover_news(_view, state), do: {nil, state}

      @impl RingTracer.Strategy
      def parent_start(_view, _options), do: {nil, []}

      @impl RingTracer.Strategy
      def parent_atom_done(_view, state, _index), do: {state, []}

      @impl RingTracer.Strategy
      def parent_frame(view, state, frame),
        do: {state, RingTracer.Strategy.strips(view, frame)}

      @impl RingTracer.Strategy
      def parent_joined(_view, state, _joined), do: {state, []}

      @impl RingTracer.Strategy
      def parent_info(_message, _view, state), do: {state, []}

      defoverridable options: 2,
                     initial_atoms: 3,
                     init: 1,
                     parts: 2,
                     handle_message: 3,
                     handover_news: 2,
                     parent_start: 2,
                     parent_atom_done: 3,
                     parent_frame: 3,
                     parent_joined: 3,
                     parent_info: 3
    end
  end

  @doc """
  The counters a strategy moves with `{:stat, key}`, each a field of a
  child's statistics (`RingTracer.Job.Stats`).

      iex> RingTracer.Strategy.stats()
      [:offers_sent, :offers_passed, :offers_consumed]
  """
  @spec stats() :: [stat()]
  def stats, do: @stats

  @doc "Whether `key` is a counter a strategy moves (`stats/0`); allowed in guards."
  defguard is_stat(key) when key in @stats

  @doc """
  Options of a strategy that takes none (`options/2`): `[]`, or an error
  naming the first one given.

      iex> RingTracer.Strategy.no_options([], :steal)
      {:ok, []}
      iex> RingTracer.Strategy.no_options([split: true], :steal)
      {:error, "strategy :steal takes no options, got: [split: true]"}
  """
  @spec no_options(options(), atom()) :: {:ok, []} | {:error, String.t()}
  def no_options([], _name), do: {:ok, []}

  def no_options(options, name),
    do: {:error, "strategy #{inspect(name)} takes no options, got: #{inspect(options)}"}

  @doc """
  Every child's strip of frame `frame`, as the parent's hand-outs (those of
  dead children too: the parent spreads them over the living). In a ring
  that children joined (the view's `size` above the layout's children),
  the frame is cut alike into `size` strips (contiguous, or interleaved as
  the layout's order is), so that the children that joined trace later
  frames too.

      iex> layout = RingTracer.Layout.new(8, 1, 2, 2) |> RingTracer.Layout.with_frames(3)
      iex> view = %RingTracer.Strategy.ParentView{spec: %{layout: layout}, pid: self()}
      iex> RingTracer.Strategy.strips(view, 2)
      [{:hand_out, 0, [8, 9]}, {:hand_out, 1, [10, 11]}]
      iex> RingTracer.Strategy.strips(%{view | size: 3}, 2)
      [{:hand_out, 0, [8]}, {:hand_out, 1, [9]}, {:hand_out, 2, [10, 11]}]
  """
  @spec strips(ParentView.t(), non_neg_integer()) :: [parent_effect()]
  def strips(%ParentView{spec: %{layout: layout}, size: size}, frame)
      when size <= layout.children do
    for i <- 0..(layout.children - 1), do: {:hand_out, i, Layout.strip(layout, i, frame)}
  end

  def strips(%ParentView{spec: %{layout: layout}, size: size}, frame) do
    atoms = Layout.frame_atoms(layout, frame)
    m = Range.size(atoms)

    for i <- 0..(size - 1) do
      share =
        case layout.order do
          :strips ->
            Enum.slice(atoms, div(i * m, size), div((i + 1) * m, size) - div(i * m, size))

          :interleaved ->
            Enum.to_list((atoms.first + i)..atoms.last//size)
        end

      {:hand_out, i, share}
    end
    |> Enum.reject(&(elem(&1, 2) == []))
  end

  @doc """
  What a child does with a message its strategy does not handle: atoms
  handed over are queued, anything else is ignored.

      iex> RingTracer.Strategy.default_message({:handover, :parent, [3]}, nil, %{})
      {%{}, [{:queue, [3]}]}
      iex> RingTracer.Strategy.default_message(:hello, nil, %{})
      {%{}, []}
  """
  @spec default_message(term(), View.t() | nil, state()) :: result(effect())
  def default_message({:handover, _from, atoms}, _view, state) when is_list(atoms),
    do: {state, [{:queue, atoms}]}

  def default_message(_message, _view, state), do: {state, []}
end
