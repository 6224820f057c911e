defmodule RingTracer.Job.Child do
  @moduledoc """
  A child: one member of the ring, owner of one strip of the image.

  Started by the job's parent under `RingTracer.Children` on the node the
  child runs on (a supervision tree cannot span nodes; the child's life is
  tied to its parent's by a monitor). It prepares its kernel (for the native
  kernel: the parsed scene from its node's `RingTracer.SceneCache`), then
  waits for `{:ring, ...}` from the parent, naming its left sibling.

  Then, as the paper has it:

    * it spawns a grandchild and keeps two atoms in its pipe (one being
      traced, one queued), so the grandchild never waits;
    * every traced atom's pixels go to the parent at once;
    * when it holds no more atoms, its strategy (`RingTracer.Strategy`)
      decides what to do: for the ring, send a help offer to the left;
    * atoms handed over (`{:handover, from, atoms}`) are queued and traced.

  A grandchild that dies is restarted and its atoms retried, at most three
  times per atom; then the child reports the atom as failed to the parent,
  which fails the job.

  Every message a child sends to another process of the job goes through
  `send_counted/4`, which counts it and its size by kind: `:result`,
  `:handover`, `:offer`, `:control`.
  """
  use GenServer, restart: :temporary

  alias RingTracer.Job.{Grandchild, Pipe, Spec}
  alias RingTracer.Layout

  @pipe_depth 2
  @max_attempts 3

  @doc false
  @spec start(node(), Spec.t(), non_neg_integer(), pid()) :: DynamicSupervisor.on_start_child()
  def start(node, %Spec{} = spec, index, parent) do
    DynamicSupervisor.start_child(
      RingTracer.Names.children(node),
      {__MODULE__, {spec, index, parent}}
    )
  end

  @doc false
  @spec start_link({Spec.t(), non_neg_integer(), pid()}) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  ## Helpers for strategies

  @doc """
  The pid of sibling `index`, from the job's directory on this node
  (`RingTracer.Job.Directory`): children do not carry the ring.
  """
  @spec sibling(map(), non_neg_integer()) :: pid()
  def sibling(state, index), do: RingTracer.Job.Directory.sibling(state.spec.id, index)

  @doc "Sends `msg` to `pid`, counting it under `kind` with its external size."
  @spec send_counted(map(), pid(), atom(), term()) :: map()
  def send_counted(state, pid, kind, msg) do
    deliver(state.spec, pid, msg, 0)
    count(state, kind, msg)
  end

  # Sends now, or later: after `extra` ms, plus a random delay of up to the
  # spec's `:chaos` ms (a test hook that delays and so reorders messages).
  defp deliver(spec, pid, msg, extra) do
    case extra + chaos_delay(spec) do
      0 -> send(pid, msg)
      ms -> Process.send_after(pid, msg, ms)
    end
  end

  defp chaos_delay(%Spec{chaos: 0}), do: 0
  defp chaos_delay(%Spec{chaos: max}), do: :rand.uniform(max + 1) - 1

  @doc false
  @spec count(map(), atom(), term()) :: map()
  def count(state, kind, msg) do
    bytes = :erlang.external_size(msg)

    update_in(
      state.traffic,
      &Map.update(&1, kind, {1, bytes}, fn {n, b} -> {n + 1, b + bytes} end)
    )
  end

  @doc "Adds one to stat `key`."
  @spec bump(map(), atom()) :: map()
  def bump(state, key), do: update_in(state.stats[key], &(&1 + 1))

  @doc "Records a protocol event (offer sent, passed, consumed...) for the timeline."
  @spec event(map(), atom(), term()) :: map()
  def event(state, kind, to) do
    at = job_time(state)
    RingTracer.Telemetry.child_event(state.spec.id, kind, state.index, to, at)
    %{state | events: [%{kind: kind, from: state.index, to: to, at_us: at} | state.events]}
  end

  @doc """
  Microseconds since the job's start (`t0`, wall clock, shared by the
  parent and every child, whatever their node).
  """
  @spec job_time(map()) :: integer()
  def job_time(%{t0: t0}), do: System.system_time(:microsecond) - t0

  @doc """
  What the child could give: `{remaining, in_flight}`, where `remaining`
  counts the queued atoms plus the one waiting in the grandchild's pipe
  (which `take_last/2` may still take back), and `in_flight` the one being
  traced.
  """
  @spec giveable(map()) :: {non_neg_integer(), non_neg_integer()}
  def giveable(state) do
    waiting = if waiting(state), do: 1, else: 0
    {length(state.queue) + waiting, length(state.in_flight) - waiting}
  end

  # The atom queued in the grandchild's pipe behind the one being traced.
  defp waiting(%{in_flight: in_flight}) when length(in_flight) == @pipe_depth,
    do: List.last(in_flight)

  defp waiting(_state), do: nil

  @doc """
  Takes up to `g` atoms to give away, farthest from being traced first: the
  last queued ones and then, if `g` asks for more, the atom waiting in the
  grandchild's pipe, if the grandchild has not started it (`Pipe.revoke/2`).
  """
  @spec take_last(map(), non_neg_integer()) :: {[Layout.atom_id()], map()}
  def take_last(state, g) do
    {keep, give} = RingTracer.Ring.HelpOffer.split_queue(state.queue, min(g, length(state.queue)))
    state = %{state | queue: keep}

    waiting = waiting(state)

    if g > length(give) and waiting != nil and Pipe.revoke(state.grandchild, waiting) do
      {[waiting | give], %{state | in_flight: List.delete(state.in_flight, waiting)}}
    else
      {give, state}
    end
  end

  @doc """
  Hands `atoms` over to sibling `to` at `pid` (possibly none: a refusal),
  then tells the parent, which keeps account of where atoms are
  (`RingTracer.Job.Ledger`): first the hand-over, so that a child dying
  between the two leaves the atoms on its own account, to be traced again,
  never lost.
  """
  @spec hand_over(map(), pid(), non_neg_integer(), [Layout.atom_id()], term()) :: map()
  def hand_over(state, pid, to, atoms, news \\ nil) do
    msg =
      if news == nil,
        do: {:handover, state.index, atoms},
        else: {:handover, state.index, atoms, news}

    state = count(state, :handover, msg)

    deliver(state.spec, pid, msg, state.spec.handover_delay)

    state =
      if atoms == [],
        do: state,
        else: send_counted(state, state.parent, :control, {:gave, state.index, to, atoms})

    update_in(state.stats.given, &(&1 + length(atoms)))
  end

  @doc """
  Queues atoms handed over to this child and starts on them. An atom it
  already holds (queued or in its grandchild's pipe) is not queued twice:
  after a failure the parent may hand out again an atom whose pixels are
  still on their way, and one atom twice in a pipe would meet its own claim
  (`RingTracer.Job.Pipe`) and be skipped.
  """
  @spec receive_atoms(map(), [Layout.atom_id()]) :: map()
  def receive_atoms(state, atoms) do
    atoms = Enum.reject(atoms, &(&1 in state.in_flight or &1 in state.queue))

    stats = %{
      state.stats
      | received: state.stats.received + length(atoms),
        handovers: state.stats.handovers + 1
    }

    %{state | queue: state.queue ++ atoms, status: :working, stats: stats}
    |> fill_pipe()
    |> maybe_idle()
  end

  @doc "A child's statistics before its first atom (also what a dead child reports)."
  @spec new_stats(non_neg_integer(), node() | nil, number(), non_neg_integer()) :: map()
  def new_stats(index, node, speed, own) do
    %{
      index: index,
      node: node,
      speed: speed,
      own: own,
      given: 0,
      received: 0,
      handovers: 0,
      traced: 0,
      offers_sent: 0,
      offers_passed: 0,
      offers_consumed: 0,
      grandchild_restarts: 0,
      busy_us: 0,
      trace_us: 0,
      first_atom_us: nil,
      last_atom_us: nil,
      rays: RingTracer.Kernel.no_rays()
    }
  end

  ## GenServer

  @impl GenServer
  def init({%Spec{} = spec, index, parent}) do
    Process.flag(:trap_exit, true)
    Process.monitor(parent)
    {kernel, _} = spec.kernel
    queue = spec.strategy.initial_atoms(spec.layout, index)

    state = %{
      spec: spec,
      index: index,
      parent: parent,
      kernel: nil,
      left: nil,
      left_index: nil,
      ring_size: 0,
      t0: 0,
      grandchild: nil,
      queue: queue,
      in_flight: [],
      current_since: 0,
      attempts: %{},
      done: 0,
      status: :waiting,
      dead: [],
      strategy_state: %{},
      early: [],
      traffic: %{},
      events: [],
      atoms: [],
      stats: new_stats(index, node(), speed(spec, index), length(queue))
    }

    {:ok, state, {:continue, {:prepare, kernel}}}
  end

  @impl GenServer
  def handle_continue({:prepare, kernel}, state) do
    {_, opts} = state.spec.kernel

    case kernel.prepare(state.spec, opts) do
      {:ok, context} ->
        {:noreply, %{state | kernel: {kernel, context}}}

      {:error, message} ->
        send(state.parent, {:child_failed, state.index, message})
        {:stop, :normal, state}
    end
  end

  @impl GenServer
  def handle_info(msg, state), do: handle(msg, state)

  defp handle({:ring, ring}, state) do
    state =
      %{
        state
        | left: ring.left,
          left_index: ring.left_index,
          ring_size: ring.size,
          t0: ring.t0,
          status: :working
      }
      |> spawn_grandchild()
      |> fill_pipe()
      |> maybe_idle()

    # Siblings (or the parent, for :master) may have written to us before the
    # parent's ring message came: handle those messages now, in order.
    Enum.each(Enum.reverse(state.early), &send(self(), &1))
    {:noreply, %{state | early: []}}
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
        rays: Map.merge(s.rays, rays, fn _, a, b -> a + b end)
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
        current_since: now(),
        attempts: Map.delete(state.attempts, atom),
        done: state.done + 1,
        stats: stats,
        atoms: [record | state.atoms]
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
    {started, waiting} = Enum.split_with(state.in_flight, &Pipe.claimed?(gc, &1))
    Pipe.forget(gc)
    state = %{state | grandchild: nil} |> bump(:grandchild_restarts)
    message = "grandchild exited: #{inspect(reason)}"

    {:noreply, retry(spawn_grandchild(state), started, message, waiting)}
  end

  defp handle({:ring_changed, ring}, %{left: left} = state) when left != nil do
    state = %{
      state
      | left: ring.left,
        left_index: ring.left_index,
        dead: ring.dead
    }

    state =
      case state.status do
        # Our offer went to a sibling that died: send a fresh one. (One
        # passed on to it later is lost too, but sending afresh whenever that
        # may be doubled every idle child's offers after each failure; the
        # job ends anyway, since the parent hands the dead child's atoms out
        # again itself.)
        :offered ->
          if Map.get(state.strategy_state, :sent_to, hd(ring.dead)) in ring.dead,
            do: maybe_idle(%{state | status: :working}),
            else: state

        # The sibling we asked may be gone; the others still trace what they hold.
        :stealing ->
          %{state | status: :finished}

        _ ->
          state
      end

    {:noreply, state}
  end

  defp handle(msg, %{left: nil} = state),
    do: {:noreply, %{state | early: [msg | state.early]}}

  # Lost atoms handed out again by the parent, which has heard from every
  # child it needed to: no more news of idleness until the next failure.
  defp handle(msg, state), do: strategy(msg, state)

  defp strategy(msg, state) do
    case state.spec.strategy.handle_message(msg, state) do
      {:ok, state} ->
        {:noreply, state}

      :unhandled ->
        case msg do
          {:handover, _from, atoms} when is_list(atoms) -> {:noreply, receive_atoms(state, atoms)}
          _ -> {:noreply, state}
        end
    end
  end

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
    gc = Grandchild.start_link(state.kernel, state.spec.layout, state.stats.speed)
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

  defp fill_pipe(%{queue: [atom | rest], in_flight: in_flight} = state)
       when length(in_flight) < @pipe_depth do
    send(state.grandchild, {:trace, atom})
    state = if in_flight == [], do: %{state | current_since: now()}, else: state
    fill_pipe(%{state | queue: rest, in_flight: in_flight ++ [atom]})
  end

  defp fill_pipe(state), do: state

  defp maybe_idle(%{queue: [], in_flight: [], status: :working} = state),
    do: state.spec.strategy.idle(state)

  defp maybe_idle(state), do: state

  defp now, do: System.monotonic_time(:microsecond)

  @doc """
  The child's speed: kernel work units traced (its `:rays` counters'
  `:work`) per microsecond its grandchild spent on atoms (wall time,
  slowdown included); `nil` until it has traced work. Unlike a count of
  atoms, it does not take a child that traced cheap atoms for a fast one.

      iex> stats = RingTracer.Job.Child.new_stats(0, node(), 1, 4)
      iex> RingTracer.Job.Child.rate(%{stats: stats})
      nil
      iex> RingTracer.Job.Child.rate(%{stats: %{stats | busy_us: 2_000, rays: %{stats.rays | work: 5_000}}})
      2.5
  """
  @spec rate(map()) :: float() | nil
  def rate(%{stats: %{rays: %{work: work}, busy_us: busy}}) when work > 0 and busy > 0,
    do: work / busy

  def rate(_state), do: nil

  @doc """
  The child's mean wall time per atom (slowdown included), `nil` before its
  first atom.
  """
  @spec mean_atom_us(map()) :: non_neg_integer() | nil
  def mean_atom_us(%{stats: %{traced: 0}}), do: nil
  def mean_atom_us(%{stats: %{busy_us: busy, traced: n}}), do: div(busy, n)

  @doc """
  How long the atom its grandchild is tracing should still take, from the
  child's mean time per atom (`nil` before its first atom).
  """
  @spec expected_remaining_us(map()) :: non_neg_integer() | nil
  def expected_remaining_us(state) do
    case mean_atom_us(state) do
      nil -> nil
      mean -> max(mean - (now() - state.current_since), 0)
    end
  end

  defp speed(%Spec{speeds: []}, _index), do: 1
  defp speed(%Spec{speeds: speeds}, index), do: Enum.at(speeds, rem(index, length(speeds)))
end
