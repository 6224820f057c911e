defmodule RingTracer.Job.Child do
  @moduledoc false
  # A child: one member of the ring, owner of one strip of the image.
  #
  # Started by the job's parent under `RingTracer.Children` on the node the
  # child runs on (a supervision tree cannot span nodes; the child's life is
  # tied to its parent's by a monitor). It prepares its kernel (for the native
  # kernel: the parsed scene from its node's `RingTracer.SceneCache`), then
  # waits for `{:ring, ...}` from the parent, naming its left sibling.
  #
  # Then, as the paper has it:
  #
  #   * it spawns a grandchild and keeps two atoms in its pipe (one being
  #     traced, one queued), so the grandchild never waits;
  #   * every traced atom's pixels go to the parent at once;
  #   * when it holds no more atoms, its strategy (`RingTracer.Strategy`)
  #     decides what to do: for the ring, send a help offer to the left;
  #   * atoms handed over (`{:handover, from, atoms}`) are queued and traced.
  #
  # A strategy sees the child through a read-only `RingTracer.Strategy.View`
  # and answers with effects, which the child carries out in one place
  # (`effect/2`): the strategy decides, the child sends,
  # counts, takes atoms from its queue and records events.
  #
  # A grandchild that dies is restarted and its atoms retried, at most three
  # times per atom; then the child reports the atom as failed to the parent,
  # which fails the job.
  #
  # Every message a child sends to another process of the job goes through
  # `send_counted/4`, which counts it and its size by kind: `:result`,
  # `:handover`, `:offer`, `:control`.

  use GenServer, restart: :temporary

  require RingTracer.Strategy

  alias RingTracer.Job.{Directory, Grandchild, Pipe, Queue, Slowdown, Spec, Stats}
  alias RingTracer.Layout
  alias RingTracer.Strategy.View

  @pipe_depth 2
  @sequence_events 10_000
  @max_attempts 3

  @enforce_keys [:spec, :index, :parent, :strategy, :stats]
  defstruct [
    :spec,
    :index,
    :parent,
    :strategy,
    :stats,
    kernel: nil,
    left: nil,
    left_index: nil,
    ring_size: 0,
    t0: 0,
    grandchild: nil,
    queue: Queue.new(),
    in_flight: [],
    parts: %{},
    current_since: 0,
    attempts: %{},
    done: 0,
    last_frame: 0,
    status: :waiting,
    dead: [],
    strategy_state: %{},
    early: [],
    traffic: %{},
    events: [],
    events_kept: 0,
    atoms: []
  ]

  @typedoc """
  A child's state: its spec, place in the ring and left sibling, its
  grandchild and the atoms queued for it (`queue`) or in its pipe
  (`in_flight`, the one being traced first), the atoms in its pipe traced in
  parts (`parts`: how many, or `:cut` for the piece left after a cut), tries
  per atom, the latest frame it has had atoms of (`last_frame`), its status,
  its strategy's state, messages that came before the ring (`early`), and
  what it reports at the end (`traffic`, `events` (in a job of several
  frames, the latest ones: `events_kept` counts them), `atoms`, `stats`).
  """
  @type t :: %__MODULE__{
          spec: Spec.t(),
          index: non_neg_integer(),
          parent: pid(),
          strategy: module(),
          stats: stats(),
          kernel: {module(), term()} | nil,
          left: pid() | nil,
          left_index: non_neg_integer() | nil,
          ring_size: non_neg_integer(),
          t0: integer(),
          grandchild: pid() | nil,
          queue: Queue.t(),
          in_flight: [Layout.atom_id()],
          parts: %{Layout.atom_id() => pos_integer() | :cut},
          current_since: integer(),
          attempts: %{Layout.atom_id() => pos_integer()},
          done: non_neg_integer(),
          last_frame: non_neg_integer(),
          status: :waiting | :working | :idle | :finished,
          dead: [non_neg_integer()],
          strategy_state: RingTracer.Strategy.state(),
          early: [term()],
          traffic: traffic(),
          events: [event()],
          events_kept: non_neg_integer(),
          atoms: [atom_record()]
        }

  @typedoc "Messages sent, by kind: `{count, bytes}` (bytes in the external term format)."
  @type traffic :: %{atom() => {non_neg_integer(), non_neg_integer()}}

  @typedoc "A process's state that counts the messages it sends (a child's or the parent's)."
  @type counting :: %{required(:traffic) => traffic(), optional(atom()) => term()}

  @typedoc "A protocol event for the timeline (see `RingTracer.Result`)."
  @type event :: RingTracer.Result.event()

  @typedoc "One traced atom's record (see `RingTracer.Result`)."
  @type atom_record :: RingTracer.Result.atom_record()

  @typedoc "A child's statistics."
  @type stats :: Stats.t()

  @typedoc "What a child reports to its parent when it stops."
  @type report :: %{
          stats: stats(),
          traffic: traffic(),
          events: [event()],
          atoms: [atom_record()]
        }

  @doc false
  @spec start(node(), Spec.t(), non_neg_integer(), pid()) :: DynamicSupervisor.on_start_child()
  def start(node, %Spec{} = spec, index, parent) do
    DynamicSupervisor.start_child(
      RingTracer.Names.children(node),
      {__MODULE__, {spec, index, parent}}
    )
  catch
    # the node dropped, or was disconnected by the job's liveness watch
    :exit, reason -> {:error, {:exit, reason}}
  end

  @doc false
  @spec start_link({Spec.t(), non_neg_integer(), pid()}) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  @doc "Sends `msg` to `pid`, counting it under `kind` with its external size."
  @spec send_counted(state, pid(), atom(), term()) :: state when state: counting()
  def send_counted(state, pid, kind, msg) do
    send(pid, msg)
    count(state, kind, msg)
  end

  defp count(state, kind, msg) do
    bytes = :erlang.external_size(msg)

    %{
      state
      | traffic: Map.update(state.traffic, kind, {1, bytes}, fn {n, b} -> {n + 1, b + bytes} end)
    }
  end

  defp bump(state, key), do: %{state | stats: Map.update!(state.stats, key, &(&1 + 1))}

  # A protocol event (offer sent, passed, consumed...) for the timeline.
  defp event(state, kind, to) do
    at = job_time(state)
    RingTracer.Telemetry.child_event(state.spec.id, kind, state.index, to, at)
    bound_events(state, [%{kind: kind, from: state.index, to: to, at_us: at} | state.events])
  end

  @doc """
  Microseconds since the job's start (`t0`, wall clock, shared by the
  parent and every child, whatever their node).
  """
  @spec job_time(%{required(:t0) => integer(), optional(atom()) => term()}) :: integer()
  def job_time(%{t0: t0}), do: System.system_time(:microsecond) - t0

  # What the child could give: `{remaining, in_flight}`, where `remaining`
  # counts the queued atoms plus the one waiting in the grandchild's pipe
  # (which `take_last/2` may still take back), and `in_flight` the one being
  # traced.
  defp giveable(state) do
    waiting = if waiting(state), do: 1, else: 0
    {Queue.size(state.queue) + waiting, length(state.in_flight) - waiting}
  end

  # The atom queued in the grandchild's pipe behind the one being traced.
  defp waiting(%{in_flight: in_flight}) when length(in_flight) == @pipe_depth,
    do: List.last(in_flight)

  defp waiting(_state), do: nil

  # Takes up to `g` whole atoms and then, with `part` `{k, n}`, the last `k`
  # of `n` parts of the next one (`RingTracer.Layout.split/3`; its head stays
  # queued): see `take_last/2`.
  defp take_last(state, g, nil), do: take_last(state, g)

  defp take_last(state, g, {k, n}) do
    {whole, state} = take_last(state, g)

    cond do
      length(whole) < g ->
        {whole, state}

      Queue.size(state.queue) > 0 ->
        {head, tail} = Layout.split(Queue.last(state.queue), n - k, n)
        state = bump(%{state | queue: Queue.replace_last(state.queue, head)}, :splits)
        {[tail | whole], state}

      true ->
        case take_last(state, 1) do
          {[atom], state} ->
            {head, tail} = Layout.split(atom, n - k, n)
            {[tail | whole], fill_pipe(bump(%{state | queue: Queue.new([head])}, :splits))}

          {[], state} ->
            {whole, state}
        end
    end
  end

  # Takes up to `g` atoms to give away, farthest from being traced first: the
  # last queued ones and then, if `g` asks for more, the atom waiting in the
  # grandchild's pipe, if the grandchild has not started it (`Pipe.revoke/2`).
  defp take_last(state, g) do
    {give, keep} = Queue.take_last(state.queue, g)
    state = %{state | queue: keep}

    waiting = waiting(state)

    if g > length(give) and waiting != nil and Pipe.revoke(state.grandchild, waiting) do
      {[waiting | give],
       %{
         state
         | in_flight: List.delete(state.in_flight, waiting),
           parts: Map.delete(state.parts, waiting)
       }}
    else
      {give, state}
    end
  end

  # Cuts the atom being traced (`Pipe.cut/3`): of the parts its grandchild
  # has not started, the first `keep` share (rounded down, in parts) is
  # queued again here, the rest is returned, to hand over. Nothing when every
  # part has started (a refusal, then).
  defp cut(%{in_flight: [atom | later], parts: parts} = state, keep) do
    with n when is_integer(n) <- Map.get(parts, atom),
         {:ok, started} <- Pipe.cut(state.grandchild, atom, n) do
      kept = started + floor((n - started) * keep)
      head = Layout.parts(atom, 0, started, n)
      parts = parts |> Map.delete(atom) |> Map.put(head, :cut)

      queue =
        if kept > started,
          do: Queue.push_front(state.queue, Layout.parts(atom, started, kept, n)),
          else: state.queue

      state = %{state | in_flight: [head | later], parts: parts, queue: queue}
      # each piece beyond the atom's first counts as a split
      state = bump(bump(state, :splits), :cuts)
      state = if kept > started and kept < n, do: bump(state, :splits), else: state
      given = if kept < n, do: [Layout.parts(atom, kept, n, n)], else: []
      {given, fill_pipe(state)}
    else
      _ -> {[], state}
    end
  end

  defp cut(state, _keep), do: {[], state}

  # Hands `atoms` over to sibling `to` at `pid` (possibly none: a refusal),
  # then tells the parent, which keeps account of where atoms are
  # (`RingTracer.Job.Ledger`): first the hand-over, so that a child dying
  # between the two leaves the atoms on its own account, to be traced again,
  # never lost.
  defp hand_over(state, pid, to, atoms, news) do
    msg =
      if news == nil,
        do: {:handover, state.index, atoms},
        else: {:handover, state.index, atoms, news}

    state = send_counted(state, pid, :handover, msg)

    state =
      if atoms == [],
        do: state,
        else: send_counted(state, state.parent, :control, {:gave, state.index, to, atoms})

    update_in(state.stats.given, &(&1 + length(atoms)))
  end

  # Queues atoms handed over to this child and starts on them. An atom it
  # already holds (queued or in its grandchild's pipe) is not queued twice:
  # after a failure the parent may hand out again an atom whose pixels are
  # still on their way, and one atom twice in a pipe would meet its own claim
  # (`RingTracer.Job.Pipe`) and be skipped.
  defp receive_atoms(state, atoms) do
    {queue, atoms} = Queue.append(state.queue, atoms, MapSet.new(state.in_flight))

    last_frame =
      Enum.reduce(atoms, state.last_frame, &max(&2, Layout.frame(state.spec.layout, &1)))

    stats = %{
      state.stats
      | received: state.stats.received + length(atoms),
        handovers: state.stats.handovers + 1
    }

    %{state | queue: queue, status: :working, stats: stats, last_frame: last_frame}
    |> fill_pipe()
    |> maybe_idle()
  end

  ## The strategy: a view in, effects out, carried out here and nowhere else

  # What the child's strategy sees of it (`RingTracer.Strategy.View`).
  defp view(%__MODULE__{} = state) do
    {remaining, in_flight} = giveable(state)
    {_, options} = state.spec.strategy

    %View{
      job: state.spec.id,
      options: options,
      index: state.index,
      pid: self(),
      ring_size: state.ring_size,
      left: state.left,
      left_index: state.left_index,
      dead: state.dead,
      status: view_status(state.status),
      queued: Queue.size(state.queue),
      last_share: share(Queue.last(state.queue) || waiting(state)),
      remaining: remaining,
      in_flight: in_flight,
      done: state.done,
      rate: rate(state),
      mean_atom_us: mean_atom_us(state),
      remaining_us: if(in_flight > 0, do: expected_remaining_us(state)),
      cuttable: cuttable(state),
      more_frames: state.last_frame < state.spec.layout.frames - 1,
      now: job_time(state)
    }
  end

  # Parts not yet started of the atom being traced, if it is traced in parts
  # (what `Pipe.cut/3` would take now, unless a part starts meanwhile).
  defp cuttable(%{in_flight: [atom | _], parts: parts, grandchild: gc}) when gc != nil do
    case Map.get(parts, atom) do
      n when is_integer(n) ->
        case Pipe.started(gc, atom) do
          0 -> 0
          started -> max(n - started, 0)
        end

      _ ->
        0
    end
  end

  defp cuttable(_state), do: 0

  defp share(nil), do: nil

  defp share(atom) do
    {k, n} = Layout.fraction(atom)
    k / n
  end

  defp view_status(:waiting), do: :working
  defp view_status(status), do: status

  # Hands `msg` to the child's strategy and carries out what it answers
  # (`RingTracer.Strategy.handle_message/3`).
  defp strategy_message(state, msg),
    do: run_strategy(state, &state.strategy.handle_message(msg, &1, &2))

  # Tells the child's strategy that the child ran out of atoms, and carries
  # out what it answers (`RingTracer.Strategy.idle/2`).
  defp idle(state), do: run_strategy(%{state | status: :idle}, &state.strategy.idle/2)

  defp run_strategy(state, callback) do
    {strategy_state, effects} = callback.(view(state), state.strategy_state)
    effects(%{state | strategy_state: strategy_state}, effects)
  end

  defp effects(state, effects), do: Enum.reduce(effects, state, &effect(&2, &1))

  defp effect(state, {:send, to, kind, msg}),
    do: send_counted(state, address(state, to), kind, msg)

  defp effect(state, {:give, pid, to, n}), do: effect(state, {:give, pid, to, n, nil})

  defp effect(state, {:give, pid, to, n, part}) do
    {atoms, state} = take_last(state, n, part)
    {news, strategy_state} = state.strategy.handover_news(view(state), state.strategy_state)
    hand_over(%{state | strategy_state: strategy_state}, pid, to, atoms, news)
  end

  defp effect(state, {:cut, pid, to, keep}) do
    {atoms, state} = cut(state, keep)
    {news, strategy_state} = state.strategy.handover_news(view(state), state.strategy_state)
    hand_over(%{state | strategy_state: strategy_state}, pid, to, atoms, news)
  end

  defp effect(state, {:queue, atoms}), do: receive_atoms(state, atoms)
  defp effect(state, {:left, pid, index}), do: %{state | left: pid, left_index: index}
  defp effect(state, :finished), do: %{state | status: :finished}
  defp effect(state, {:event, kind, to}), do: event(state, kind, to)

  defp effect(state, {:stat, key}) when RingTracer.Strategy.is_stat(key), do: bump(state, key)

  defp effect(state, {:continue, msg}), do: strategy_message(state, msg)

  defp address(state, :parent), do: state.parent
  defp address(state, {:sibling, index}), do: Directory.sibling(state.spec.id, index)
  defp address(_state, pid) when is_pid(pid), do: pid

  ## GenServer

  @impl GenServer
  def init({%Spec{} = spec, index, parent}) do
    Process.flag(:trap_exit, true)
    Process.monitor(parent)
    {kernel, _} = spec.kernel
    {strategy, options} = spec.strategy
    # A child that joins a running job (`RingTracer.grow/4`) starts with none.
    queue = RingTracer.Job.Ledger.initial_atoms({spec.layout, spec.strategy}, index)

    state = %__MODULE__{
      spec: spec,
      index: index,
      parent: parent,
      t0: spec.t0 || System.system_time(:microsecond),
      strategy: strategy,
      strategy_state: strategy.init(options),
      queue: Queue.new(queue),
      stats:
        Stats.new(
          index,
          node(),
          Spec.speed(List.to_tuple(spec.speeds), index) * Slowdown.node_speed(),
          length(queue)
        )
    }

    {:ok, state, {:continue, {:prepare, kernel}}}
  end

  @impl GenServer
  def handle_continue({:prepare, kernel}, state) do
    {_, opts} = state.spec.kernel

    case kernel.prepare(state.spec, opts) do
      {:ok, context} ->
        # Its strip's atoms go to the grandchild at once, before the ring
        # reaches it: a child needs its siblings only once it runs out.
        state = %{state | kernel: {kernel, context}} |> spawn_grandchild() |> fill_pipe()
        {:noreply, state}

      {:error, message} ->
        send(state.parent, {:child_failed, state.index, message})
        {:stop, :normal, state}
    end
  end

  @impl GenServer
  def handle_info(msg, state), do: handle(msg, state)

  defp handle({:ring, ring}, state) do
    with :ok <- await_ring(state, ring.size), do: ring_started(ring, state)
  end

  # Siblings joined the ring (`RingTracer.grow/4`): the ring is larger, and
  # the lowest child's left sibling is now the highest that joined.
  defp handle({:ring_grown, ring}, %{left: left} = state) when left != nil do
    with :ok <- await_ring(state, ring.size) do
      state = %{state | ring_size: ring.size}

      state =
        if ring.left, do: %{state | left: ring.left, left_index: ring.left_index}, else: state

      {:noreply, strategy_message(state, {:siblings_joined, ring.joined})}
    end
  end

  defp handle({:traced, gc, atom, pixels, rays, timing}, %{grandchild: gc} = state) do
    Pipe.release(gc, atom)

    state =
      send_counted(
        state,
        state.parent,
        :result,
        {:atom_done, state.index, atom, pixels, rays, timing.trace_us}
      )

    started = timing.started_at - state.t0
    ended = timing.ended_at - state.t0
    s = state.stats

    stats = %{
      s
      | traced: s.traced + 1,
        busy_us: s.busy_us + (ended - started),
        trace_us: s.trace_us + timing.trace_us,
        first_atom_us: s.first_atom_us || started,
        last_atom_us: ended,
        rays: RingTracer.Rays.add(s.rays, rays)
    }

    record = %{
      atom: atom,
      owner: Layout.owner(state.spec.layout, atom),
      child: state.index,
      start_us: started,
      end_us: ended,
      trace_us: timing.trace_us
    }

    state = %{
      state
      | in_flight: List.delete(state.in_flight, atom),
        parts: Map.delete(state.parts, atom),
        current_since: now(),
        attempts: Map.delete(state.attempts, atom),
        done: state.done + 1,
        stats: stats,
        atoms: keep_record(state, record)
    }

    {:noreply, state |> fill_pipe() |> maybe_idle()}
  end

  defp handle({:atom_failed, gc, atom, message}, %{grandchild: gc} = state) do
    {:noreply, retry(state, [atom], message)}
  end

  defp handle({:stop, parent}, %{parent: parent} = state) do
    report = %{
      stats: state.stats,
      traffic: state.traffic,
      events: Enum.reverse(state.events),
      atoms: Enum.reverse(state.atoms)
    }

    send(parent, {:child_stopped, state.index, report})
    {:stop, :normal, state}
  end

  defp handle({:DOWN, _ref, :process, parent, _reason}, %{parent: parent} = state) do
    {:stop, :normal, state}
  end

  defp handle({:EXIT, gc, reason}, %{grandchild: gc} = state) when reason != :normal do
    # Only atoms the grandchild had started count an attempt: the one
    # waiting behind it in its pipe was never tried.
    {started, waiting} =
      Enum.split_with(state.in_flight, &(Pipe.claimed?(gc, &1) or state.parts[&1] == :cut))

    Pipe.forget(gc)
    state = bump(%{state | grandchild: nil, parts: %{}}, :grandchild_restarts)
    message = "grandchild exited: #{inspect(reason)}"

    {:noreply, retry(spawn_grandchild(state), started, message, waiting)}
  end

  defp handle({:ring_changed, ring}, %{left: left} = state) when left != nil do
    state = %{state | left: ring.left, left_index: ring.left_index, dead: ring.dead}
    {:noreply, strategy_message(state, {:siblings_died, ring.dead})}
  end

  defp handle(msg, %{left: nil} = state),
    do: {:noreply, %{state | early: [msg | state.early]}}

  # Atoms a sibling handed over: confirmed to the parent first, so that
  # they are no longer counted in transit with the giver
  # (`RingTracer.Job.Ledger.received/3`).
  defp handle({:handover, from, [_ | _] = atoms} = msg, state) when is_integer(from),
    do: {:noreply, state |> confirm(from, atoms) |> strategy_message(msg)}

  defp handle({:handover, from, [_ | _] = atoms, _news} = msg, state) when is_integer(from),
    do: {:noreply, state |> confirm(from, atoms) |> strategy_message(msg)}

  defp handle(msg, state), do: {:noreply, strategy_message(state, msg)}

  defp ring_started(ring, state) do
    state =
      %{
        state
        | left: ring.left,
          left_index: ring.left_index,
          ring_size: ring.size,
          status: :working
      }
      |> fill_pipe()
      |> maybe_idle()

    # Siblings (or the parent, for :master) may have written to us before the
    # parent's ring message came: handle those messages now, in order.
    Enum.each(Enum.reverse(state.early), &send(self(), &1))
    {:noreply, %{state | early: []}}
  end

  # The parent publishes the ring on this node (`Directory.publish/4`)
  # just before it tells the children: wait, within the liveness timeout,
  # until this node's table holds it.
  defp await_ring(state, size) do
    case Directory.await(state.spec.id, size, state.spec.liveness) do
      :ok ->
        :ok

      {:error, :timeout} ->
        message =
          "the job's ring of #{size} children did not reach #{node()} within " <>
            "#{state.spec.liveness} ms"

        send(state.parent, {:child_failed, state.index, message})
        {:stop, :normal, state}
    end
  end

  defp confirm(state, from, atoms),
    do: send_counted(state, state.parent, :control, {:got, from, state.index, atoms})

  @impl GenServer
  def terminate(_reason, state) do
    if state.grandchild, do: stop_grandchild(state.grandchild)
    :ok
  end

  # Re-sends the given atoms to a (new) grandchild, or gives up on an atom
  # that has failed too often.
  defp retry(state, atoms, message, untried \\ []) do
    {state, failed} =
      Enum.reduce(atoms, {state, nil}, fn atom, {st, failed} ->
        n = Map.get(st.attempts, atom, 1)

        if n >= @max_attempts do
          {st, failed || {atom, message}}
        else
          {%{st | attempts: Map.put(st.attempts, atom, n + 1)}, failed}
        end
      end)

    case failed do
      nil ->
        state = if state.grandchild, do: state, else: spawn_grandchild(state)
        # Retried whole: a cut must not take parts of them any more.
        state = %{state | parts: Map.drop(state.parts, atoms ++ untried)}

        Enum.each(atoms ++ untried, fn atom ->
          Pipe.release(state.grandchild, atom)
          send(state.grandchild, {:trace, atom})
        end)

        state

      {atom, message} ->
        send_counted(state, state.parent, :control, {:atom_failed, state.index, atom, message})
    end
  end

  defp spawn_grandchild(state) do
    %Spec{pixels: format, tint: tint?} = state.spec
    wire = %{format: format, tint: if(tint?, do: RingTracer.Report.Palette.linear(state.index))}
    gc = Grandchild.start_link(state.kernel, state.spec.layout, state.stats.speed, wire)
    %{state | grandchild: gc}
  end

  defp stop_grandchild(gc) do
    ref = Process.monitor(gc)
    Process.unlink(gc)
    Process.exit(gc, :kill)

    receive do
      {:DOWN, ^ref, _, _, _} -> Pipe.forget(gc)
    end
  end

  defp fill_pipe(state) when length(state.in_flight) < @pipe_depth do
    case Queue.next(state.queue) do
      {atom, rest} -> fill_pipe(%{state | queue: rest}, atom)
      :empty -> state
    end
  end

  defp fill_pipe(state), do: state

  defp fill_pipe(state, atom) do
    state =
      case parts_of(state, atom) do
        1 ->
          send(state.grandchild, {:trace, atom})
          state

        n ->
          send(state.grandchild, {:trace, atom, n})
          %{state | parts: Map.put(state.parts, atom, n)}
      end

    state = if state.in_flight == [], do: %{state | current_since: now()}, else: state
    fill_pipe(%{state | in_flight: state.in_flight ++ [atom]})
  end

  # In how many parts the grandchild traces `atom` (the strategy's
  # `parts/2`, which sees the atom's rows).
  defp parts_of(state, atom) do
    {_, count} = Layout.span(state.spec.layout, atom)
    view = %{view(state) | next_rows: count / state.spec.layout.width}

    max(state.strategy.parts(view, state.strategy_state), 1)
  end

  # A job of several frames keeps its latest @sequence_events events (at
  # most twice as many between two cuts), so that its memory does not grow
  # with the number of frames; one image keeps them all.
  defp bound_events(%{spec: %Spec{layout: %Layout{frames: 1}}} = state, events),
    do: %{state | events: events}

  defp bound_events(%{events_kept: n} = state, events) when n >= 2 * @sequence_events,
    do: %{state | events: Enum.take(events, @sequence_events), events_kept: @sequence_events}

  defp bound_events(state, events),
    do: %{state | events: events, events_kept: state.events_kept + 1}

  # Each atom's record, for the timeline and ownership map of one image; a
  # job of several frames keeps none, so that its memory does not grow
  # with the number of frames.
  defp keep_record(%{spec: %Spec{layout: %Layout{frames: 1}}} = state, record),
    do: [record | state.atoms]

  defp keep_record(state, _record), do: state.atoms

  defp maybe_idle(%{queue: %Queue{size: 0}, in_flight: [], status: :working} = state),
    do: idle(state)

  defp maybe_idle(state), do: state

  defp now, do: System.monotonic_time(:microsecond)

  defp rate(state), do: Stats.rate(state.stats)
  defp mean_atom_us(state), do: Stats.mean_atom_us(state.stats)

  # How long the atom its grandchild is tracing should still take, from the
  # child's mean time per atom (`nil` before its first atom).
  defp expected_remaining_us(state) do
    case mean_atom_us(state) do
      nil -> nil
      mean -> max(mean - (now() - state.current_since), 0)
    end
  end
end
