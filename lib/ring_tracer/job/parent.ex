defmodule RingTracer.Job.Parent do
  @moduledoc false
  # The parent of one render job: it starts the children, links them in a
  # ring, receives every atom's pixels, and ends the job.
  #
  # The job is complete when the parent holds every atom, whole or in pieces
  # (`RingTracer.Job.Coverage`); that, not the ring's tokens, is the
  # termination test, because atoms handed over between children may still be
  # in flight when an offer returns. An atom (or a piece) that brings nothing
  # new is counted as a duplicate. On completion the parent sends each
  # child the stop message, waits until every child has stopped and reported
  # its statistics (a child kills its grandchild first), sends the result to
  # the caller and stops: no process of the job outlives it.
  #
  # ## Frames
  #
  # A job of several frames (`RingTracer.Layout`, "Frames") keeps at most
  # its spec's `window` of frames in flight: the first frame's atoms are the
  # children's initial atoms, and each time the oldest frame in flight
  # completes, the next frame is released (`RingTracer.Strategy.parent_frame/3`:
  # by default each child gets its strip of it, queued behind what it holds).
  # A child that runs out goes on with the next frame's atoms or helps its
  # siblings, so the ring does not drain between frames. In a `sequence`,
  # the parent sends each frame to the caller as it completes
  # (`RingTracer.Frame`) and forgets its pixels, its atoms' coverage and
  # their places in the ledger: memory holds the window, whatever the
  # number of frames. With the spec's `ack`, a frame sent stays in the
  # window until the caller acknowledges it (`{:frame_ack, n}`, e.g. once it
  # is written), so that a caller slower than the ring holds the frames back
  # instead of letting them pile up in its mailbox.
  #
  # If the caller dies, the job stops. If a child dies, the atoms it may have
  # held are handed out again at once (`RingTracer.Job.Ledger`) and the ring
  # is re-linked around it; if an atom fails for good, or every child dies,
  # the job fails with the reason.
  #
  # ## An elastic ring
  #
  # Children can join a running job (`{:grow, from, ref, node, count}`, from
  # `RingTracer.grow/4`): the parent prepares the node if the job has not
  # used it yet (the scene shipped and pinned there), starts the children
  # with the next indices and no atoms, publishes the larger ring on every
  # node, sends each new child `{:ring, ...}` with the highest child before
  # it as its left sibling, and tells the others `{:ring_grown, ...}` (the
  # lowest child's left sibling is now the highest that joined). A new
  # child starts idle and finds work through its strategy
  # (`RingTracer.Strategy.parent_joined/3` for the parent's side); later
  # frames are cut over every child. Children leave (`{:shrink, from, ref,
  # node}`, from `RingTracer.shrink/3`) by the stop message: each reports
  # and stops, and the atoms it may have held are handed out again as a
  # dead child's are, without counting as a failure.
  use GenServer, restart: :temporary

  alias RingTracer.Job.{Child, Coverage, Directory, Ledger, Spec}
  alias RingTracer.Layout
  alias RingTracer.Strategy.ParentView

  @doc false
  @spec start(Spec.t()) :: DynamicSupervisor.on_start_child()
  def start(%Spec{} = spec) do
    DynamicSupervisor.start_child(RingTracer.Names.jobs(), {__MODULE__, spec})
  end

  @doc false
  @spec start_link(Spec.t()) :: GenServer.on_start()
  def start_link(spec), do: GenServer.start_link(__MODULE__, spec)

  # The tag of the messages to the job's caller and progress pid, as
  # `RingTracer.render/2` documents them. An atom, not the alias: the parent
  # calls nothing of the public API module (no run-time dependency on it).
  @reply_tag :"Elixir.RingTracer"

  @enforce_keys [:spec, :strategy, :ledger, :missing, :started, :t0]
  defstruct [
    :spec,
    :strategy,
    :ledger,
    :missing,
    :started,
    :t0,
    completed: nil,
    children: %{},
    monitors: %{},
    frames: %{},
    released: 0,
    low: 0,
    done_above: MapSet.new(),
    kept: 0,
    kept_above: MapSet.new(),
    numbers: %{},
    traced_counts: %{},
    kept_trace_us: 0,
    summaries: [],
    coverage: %{},
    traced_by: %{},
    stopping: nil,
    strategy_state: nil,
    traffic: %{},
    duplicates: 0,
    dead: %{},
    relinking: false,
    redone: 0,
    node_bytes: %{},
    helpers: [],
    reported: 0,
    size: 0,
    pids: %{},
    placement: %{},
    watched: MapSet.new(),
    leaving: MapSet.new(),
    departed: %{}
  ]

  @typedoc """
  The parent's state: its spec and strategy module, when it started and
  completed (monotonic microseconds) and the job's wall-clock start `t0`,
  the living children and their monitors, the frames in flight (`frames`:
  the atoms received of each), how many frames are released, the oldest
  frame in flight (`low`) and the later ones already complete
  (`done_above`), the oldest frame the caller may still hold unacknowledged
  (`kept`) and the later ones it has acknowledged (`kept_above`), and
  (with `ack`) each frame's index by its number in the scene (`numbers`), who traced the atoms in flight and how many each child
  traced, how many atoms are missing, the ledger of where atoms are, the
  dead children, and what it reports (`summaries`: the frames sent, newest
  first). `size` is how many children the job has started (indices
  `0..size - 1`, those that joined included), `pids` and `placement`
  every one's pid and node, `watched` the nodes the liveness watch covers,
  `leaving` the children asked to leave and `departed` the reports of
  those that left.
  """
  @type t :: %__MODULE__{
          spec: Spec.t(),
          strategy: module(),
          ledger: Ledger.t(),
          missing: non_neg_integer(),
          started: integer(),
          t0: integer(),
          completed: integer() | nil,
          children: %{non_neg_integer() => pid()},
          monitors: %{reference() => non_neg_integer()},
          frames: %{non_neg_integer() => frame()},
          released: non_neg_integer(),
          low: non_neg_integer(),
          done_above: MapSet.t(non_neg_integer()),
          kept: non_neg_integer(),
          kept_above: MapSet.t(non_neg_integer()),
          numbers: %{pos_integer() => non_neg_integer()},
          traced_counts: %{non_neg_integer() => non_neg_integer()},
          kept_trace_us: non_neg_integer(),
          summaries: [RingTracer.Frame.t()],
          coverage: Coverage.t(),
          traced_by: %{Layout.atom_id() => non_neg_integer()},
          stopping: stopping() | nil,
          strategy_state: RingTracer.Strategy.state(),
          traffic: Child.traffic(),
          duplicates: non_neg_integer(),
          dead: %{non_neg_integer() => failure()},
          relinking: boolean(),
          redone: non_neg_integer(),
          node_bytes: %{node() => non_neg_integer()},
          helpers: [{pid(), reference()}],
          reported: non_neg_integer(),
          size: non_neg_integer(),
          pids: %{non_neg_integer() => pid()},
          placement: %{non_neg_integer() => node()},
          watched: MapSet.t(node()),
          leaving: MapSet.t(non_neg_integer()),
          departed: %{non_neg_integer() => Child.report()}
        }

  @typedoc """
  A frame in flight: the atoms received (atom or piece => pixels, in the
  job's format; `tinted`: their copies for the ownership map, with a tint), how
  many atoms are missing, and what its `RingTracer.Frame` reports.
  """
  @type frame :: %{
          results: %{Layout.atom_id() => binary()},
          tinted: %{Layout.atom_id() => binary()},
          missing: non_neg_integer(),
          released_us: integer(),
          traced: %{non_neg_integer() => non_neg_integer()},
          rays: RingTracer.Rays.t()
        }

  @typedoc "A job that is stopping: its outcome, and the reports of the children so far."
  @type stopping :: %{
          outcome: :ok | {:error, String.t()},
          reports: %{non_neg_integer() => Child.report()}
        }

  @typedoc "A child that died mid-job (see `RingTracer.Result`)."
  @type failure :: RingTracer.Result.failure()

  @typedoc "Per node (see `RingTracer.Result`)."
  @type node_summary :: RingTracer.Result.node_summary()

  @typedoc "What the parent replies to the job's caller when the job completes."
  @type reply :: %{
          pixels: binary() | nil,
          pixel_format: RingTracer.Pixels.format(),
          tinted: binary() | nil,
          frames: [RingTracer.Frame.t()],
          kept_trace_us: non_neg_integer(),
          started_at_us: integer(),
          elapsed_us: non_neg_integer(),
          teardown_us: non_neg_integer(),
          children: [Child.stats()],
          atoms: [Child.atom_record()],
          events: [Child.event()],
          traffic: Child.traffic(),
          duplicates: non_neg_integer(),
          failures: [failure()],
          redone: non_neg_integer(),
          nodes: %{node() => node_summary()},
          layout: Layout.order()
        }

  defp send_counted(state, pid, kind, msg), do: Child.send_counted(state, pid, kind, msg)

  # Hands `atoms` to child `index` (a strategy's hand-out, or atoms lost
  # with a dead child), and records it in the job's `RingTracer.Job.Ledger`.
  defp hand_out(state, index, atoms) do
    state =
      send_counted(
        state,
        Map.fetch!(state.children, index),
        :handover,
        {:handover, :parent, atoms}
      )

    moved(state, :parent, index, atoms)
    %{state | ledger: Ledger.moved(state.ledger, :parent, index, atoms)}
  end

  defp moved(state, from, to, atoms) do
    RingTracer.Telemetry.execute(
      [:ring_tracer, :atoms, :moved],
      %{atoms: length(atoms)},
      %{job: state.spec.id, from: from, to: to}
    )
  end

  # Applies `{m, f, a}` in a process of the job's (for a strategy: the ring's
  # work preview), which sends the parent `{tag, value}`; monitored by the
  # parent, which ends it and waits for it when the job ends: no process of
  # a job outlives it.
  defp start_helper(state, tag, {m, f, a}) do
    parent = self()
    {pid, ref} = spawn_monitor(fn -> send(parent, {tag, apply(m, f, a)}) end)
    %{state | helpers: [{pid, ref} | state.helpers]}
  end

  ## The strategy: a view in, effects out, carried out here

  defp view(state) do
    {_, options} = state.spec.strategy

    %ParentView{
      spec: state.spec,
      options: options,
      pid: self(),
      children: state.children,
      size: state.size,
      traced_by: state.traced_by,
      now: Child.job_time(state)
    }
  end

  defp run_strategy(state, callback) do
    {strategy_state, effects} = callback.(view(state), state.strategy_state)
    Enum.reduce(effects, %{state | strategy_state: strategy_state}, &effect(&2, &1))
  end

  defp effect(state, {:send, index, kind, msg}),
    do: send_counted(state, Map.fetch!(state.children, index), kind, msg)

  defp effect(state, {:hand_out, index, atoms}) when is_map_key(state.children, index),
    do: hand_out(state, index, atoms)

  # A dead child's share (its strip of a new frame): spread over the living.
  defp effect(state, {:hand_out, _index, atoms}), do: spread(state, atoms)
  defp effect(state, {:helper, tag, mfa}), do: start_helper(state, tag, mfa)

  @doc """
  What a preview (`RingTracer.Preview`) needs of a running job: its id,
  start time, layout, strategy, the node and speed of each child, and the
  atoms traced so far (`results`: atom => pixels, in `format`, a
  `RingTracer.Pixels` format; `traced_by`: atom => child). With `progress` given, only a job that reports its progress to
  that pid answers (`{:error, :other_job}` otherwise).
  """
  @spec describe(pid(), pid() | nil) :: {:ok, map()} | {:error, :other_job}
  def describe(parent, progress \\ nil), do: GenServer.call(parent, {:describe, progress})

  # What `describe/2` answers, and the job's start event carries (so that a
  # preview that runs after the job has ended still knows it).
  defp description(state) do
    n = state.spec.layout.children
    speeds = List.to_tuple(state.spec.speeds)

    %{
      id: state.spec.id,
      t0: state.t0,
      layout: state.spec.layout,
      strategy: state.spec.strategy,
      nodes: placement(state.spec.nodes, n),
      speeds: for(i <- 0..(n - 1), do: Spec.speed(speeds, i)),
      results: oldest_results(state),
      format: state.spec.pixels,
      traced_by: state.traced_by
    }
  end

  @impl GenServer
  def init(%Spec{} = spec) do
    Process.monitor(spec.caller)
    {strategy, _} = spec.strategy

    # Where acknowledgements go (before any frame, from this process).
    if spec.ack or spec.announce,
      do: send(spec.progress || spec.caller, {@reply_tag, spec.id, {:parent, self()}})

    # The job's clock starts here; its children read it from the spec, as
    # they may trace before the ring reaches them.
    t0 = System.system_time(:microsecond)
    spec = %{spec | t0: t0}

    state = %__MODULE__{
      spec: spec,
      strategy: strategy,
      started: System.monotonic_time(:microsecond),
      t0: t0,
      missing: Layout.atom_count(spec.layout),
      ledger: Ledger.new(spec.layout, spec.strategy),
      numbers:
        if(spec.ack,
          do: spec.frames |> Enum.with_index() |> Map.new(fn {frame, f} -> {frame + 1, f} end),
          else: %{}
        )
    }

    {:ok, state, {:continue, :start_ring}}
  end

  @impl GenServer
  def handle_continue(:start_ring, state) do
    RingTracer.Telemetry.execute(
      [:ring_tracer, :job, :start],
      %{system_time: System.system_time()},
      %{
        job: state.spec.id,
        children: state.spec.layout.children,
        atoms: state.missing,
        strategy: state.strategy,
        description: description(state)
      }
    )

    %Spec{layout: layout, nodes: nodes} = state.spec
    n = layout.children
    placement = placement(nodes, n)
    speeds = List.to_tuple(state.spec.speeds)

    # The watch starts before the nodes are asked for anything: a node that
    # freezes while the job starts is disconnected after the liveness
    # timeout, so that starting the job there fails then, not after
    # distribution's minute.
    _ = RingTracer.Cluster.Liveness.start(placement, state.spec.liveness)
    state = %{state | watched: MapSet.new(placement)}

    # Every node at once, the scene by hash, then packed to those that lack
    # it (`RingTracer.Job.Start`); each child gets its own speed: nothing in
    # a child's spec grows with the ring.
    plan =
      placement
      |> Enum.with_index()
      |> Enum.group_by(&elem(&1, 0), fn {_, i} -> {i, Spec.speed(speeds, i)} end)

    case RingTracer.Job.Start.run(state.spec, plan) do
      {:ok, list, bytes} ->
        children = Map.new(list)
        monitors = Map.new(list, fn {i, pid} -> {Process.monitor(pid), i} end)

        state = %{
          state
          | node_bytes: bytes,
            children: children,
            monitors: monitors,
            size: n,
            pids: children,
            placement: placement |> Enum.with_index() |> Map.new(fn {node, i} -> {i, node} end)
        }

        publish(state)

        state =
          Enum.reduce(children, state, fn {i, pid}, st ->
            left = rem(i - 1 + n, n)

            ring = %{
              left: Map.fetch!(children, left),
              left_index: left,
              size: n,
              t0: st.t0
            }

            send_counted(st, pid, :control, {:ring, ring})
          end)

        {_, options} = state.spec.strategy

        state =
          state
          |> new_frame(0)
          |> run_strategy(fn view, _ -> state.strategy.parent_start(view, options) end)
          |> release()

        {:noreply, state}

      {:error, reason, message, list} ->
        for {_i, pid} <- list, do: Process.exit(pid, :kill)
        send(state.spec.caller, {@reply_tag, state.spec.id, {:error, {reason, message}}})
        {:stop, :normal, state}
    end
  end

  # The ring, once per node its living children run on
  # (`RingTracer.Job.Directory`): every child's pid by index, those of dead
  # children included. A message, sent before the children are told of
  # the ring; each child waits for it on its node.
  defp publish(state) do
    pids = List.to_tuple(for i <- 0..(state.size - 1), do: Map.fetch!(state.pids, i))

    state.children
    |> Map.keys()
    |> Enum.map(&Map.fetch!(state.placement, &1))
    |> Enum.uniq()
    |> Enum.each(&Directory.publish(&1, state.spec.id, self(), pids))
  end

  @impl GenServer
  def handle_call({:describe, progress}, _from, state) do
    if progress == nil or progress == state.spec.progress,
      do: {:reply, {:ok, description(state)}, state},
      else: {:reply, {:error, :other_job}, state}
  end

  @impl GenServer
  # `RingTracer.grow/4` and `shrink/3`: `ref` is an alias of the caller's.
  def handle_info({:grow, ref, node, count}, %{stopping: nil} = state)
      when is_integer(count) and count > 0 do
    {reply, state} = grow(state, node, count)
    :erlang.send(ref, {ref, reply})
    {:noreply, state}
  end

  def handle_info({:shrink, ref, node}, %{stopping: nil} = state) do
    {reply, state} = shrink(state, node)
    :erlang.send(ref, {ref, reply})
    {:noreply, state}
  end

  def handle_info({:grow, ref, _node, _count}, state), do: ended(state, ref)
  def handle_info({:shrink, ref, _node}, state), do: ended(state, ref)

  # A child that was asked to leave reports as it stops.
  def handle_info({:child_stopped, index, report}, %{stopping: nil} = state) do
    if MapSet.member?(state.leaving, index),
      do: {:noreply, %{state | departed: Map.put(state.departed, index, report)}},
      else: {:noreply, state}
  end

  def handle_info({:atom_done, child, atom, pixels, rays, us}, state) do
    case add(state, atom) do
      # A second copy (an atom handed out again after a failure whose first
      # pixels were still on their way): counted, also while the job stops,
      # so that every result message sent is either kept or counted here.
      {:duplicate, _} ->
        {:noreply, %{state | duplicates: state.duplicates + 1}}

      {:new, coverage} when state.stopping == nil ->
        atom_done(state, coverage, child, atom, pixels, rays, us)

      {:new, _} ->
        {:noreply, state}
    end
  end

  def handle_info({:atom_failed, child, atom, message}, %{stopping: nil} = state) do
    fail(state, "atom #{inspect(atom)} failed on child #{child}: #{message}")
  end

  def handle_info({:child_failed, child, message}, %{stopping: nil} = state) do
    fail(state, "child #{child} failed: #{message}")
  end

  def handle_info({:child_stopped, index, report}, %{stopping: stopping} = state)
      when is_map(stopping) do
    {:noreply,
     %{state | stopping: %{stopping | reports: Map.put(stopping.reports, index, report)}}}
  end

  def handle_info({:DOWN, ref, :process, _pid, reason}, state) do
    if List.keymember?(state.helpers, ref, 1),
      do: {:noreply, %{state | helpers: List.keydelete(state.helpers, ref, 1)}},
      else: down(state, ref, reason)
  end

  def handle_info({:frame_ack, number}, %{stopping: nil} = state) do
    f = Map.get(state.numbers, number)

    if is_integer(f) and frame_done?(state, f) and f >= state.kept and
         not MapSet.member?(state.kept_above, f),
       do: {:noreply, state |> acked(f) |> release()},
       else: {:noreply, state}
  end

  def handle_info(:relink, %{stopping: nil} = state),
    do: {:noreply, relink(%{state | relinking: false})}

  def handle_info({:gave, from, to, atoms}, %{stopping: nil} = state) do
    if is_map_key(state.dead, to) do
      # Given to a child already dead: lost with it, so handed out again.
      state = %{state | ledger: Ledger.moved(state.ledger, from, :nobody, atoms)}
      {:noreply, reassign(state, atoms)}
    else
      moved(state, from, to, atoms)
      {:noreply, %{state | ledger: Ledger.moved(state.ledger, from, to, atoms)}}
    end
  end

  # A child confirms atoms a sibling handed it: no longer in transit
  # (`RingTracer.Job.Ledger.received/3`). From a giver already dead they
  # were handed out again at its death: nothing to do.
  def handle_info({:got, from, _to, atoms}, %{stopping: nil} = state) do
    if is_map_key(state.dead, from),
      do: {:noreply, state},
      else: {:noreply, %{state | ledger: Ledger.received(state.ledger, from, atoms)}}
  end

  # Anything else is for the strategy (`parent_info/3`).
  def handle_info(other, %{stopping: nil} = state),
    do: {:noreply, run_strategy(state, &state.strategy.parent_info(other, &1, &2))}

  def handle_info(_other, state), do: {:noreply, state}

  defp atom_done(state, coverage, child, atom, sent, rays, us) do
    %Spec{layout: layout} = state.spec
    base = Layout.base(atom)

    case decode(state.spec, atom, sent) do
      {:error, message} ->
        fail(state, "atom #{inspect(atom)} came back with #{message}")

      {:ok, pixels, tinted} ->
        # An atom counts once all of it has arrived (pieces tile it).
        done = if Coverage.complete?(coverage, base), do: 1, else: 0
        f = Layout.frame(layout, base)

        frame =
          state.frames
          |> Map.fetch!(f)
          |> Map.update!(:results, &Map.put(&1, atom, pixels))
          |> Map.update!(:tinted, &if(tinted, do: Map.put(&1, atom, tinted), else: &1))
          |> Map.update!(:missing, &(&1 - done))
          |> Map.update!(:traced, &Map.update(&1, child, 1, fn n -> n + 1 end))
          |> Map.update!(:rays, &RingTracer.Rays.add(&1, rays))

        state = %{
          state
          | frames: Map.put(state.frames, f, frame),
            coverage: coverage,
            traced_by: Map.put(state.traced_by, atom, child),
            traced_counts: Map.update(state.traced_counts, child, 1, &(&1 + 1)),
            kept_trace_us: state.kept_trace_us + us,
            missing: state.missing - done
        }

        state = if done == 1, do: progress(state), else: state
        atom_event(state, child, atom, pixels, rays, us)
        state = if frame.missing == 0, do: frame_done(state, f), else: state

        cond do
          state.missing == 0 ->
            stop_children(state)

          true ->
            {:noreply, run_strategy(state, &state.strategy.parent_atom_done(&1, &2, child))}
        end
    end
  end

  # An atom's pixels as a grandchild sent them (`RingTracer.Job.Grandchild`),
  # decoded in the job's format, and with a tint their tinted copy: the right
  # number of pixels, or an error that says what came instead.
  defp decode(%Spec{layout: layout, pixels: format, tint: tint?}, atom, sent) do
    {_first, count} = Layout.span(layout, atom)

    case {sent, tint?} do
      {{pixels, tinted}, true} ->
        with {:ok, pixels} <- decode_one(pixels, format, count),
             {:ok, tinted} <- decode_one(tinted, :srgb8, count),
             do: {:ok, pixels, tinted}

      {pixels, false} when is_binary(pixels) ->
        with {:ok, pixels} <- decode_one(pixels, format, count), do: {:ok, pixels, nil}

      _ ->
        {:error,
         "something other than its #{count} pixels" <> if(tint?, do: " and tint", else: "")}
    end
  end

  defp decode_one(pixels, format, count) when is_binary(pixels) do
    case RingTracer.Pixels.decode(pixels, format, count) do
      {:ok, decoded} ->
        {:ok, decoded}

      {:error, message} ->
        {:error,
         "#{byte_size(pixels)} bytes that are not its #{count} pixels " <>
           "(#{RingTracer.Pixels.size(count, format)} bytes of #{format}): #{message}"}
    end
  end

  defp decode_one(_other, _format, count),
    do: {:error, "something other than its #{count} pixels"}

  ## An elastic ring

  defp ended(state, ref) do
    :erlang.send(ref, {ref, {:error, :job_ended}})
    {:noreply, state}
  end

  defp check_size(size, count) do
    case RingTracer.Job.Elastic.check_size(size, count) do
      :ok -> :ok
      {:error, message} -> {:error, {:invalid_option, message}}
    end
  end

  # `count` children join the ring on `node`, with the next indices.
  defp grow(state, node, count) do
    first = state.size
    joined = Enum.to_list(first..(first + count - 1))

    with :ok <- check_size(first, count),
         {:ok, state, started} <- start_joined(state, node, joined) do
      state = state |> watch(node) |> splice(node, started)

      RingTracer.Telemetry.execute(
        [:ring_tracer, :job, :grown],
        %{children: length(joined), system_time: System.system_time()},
        %{job: state.spec.id, node: node, joined: joined, size: state.size}
      )

      {{:ok, joined}, run_strategy(state, &state.strategy.parent_joined(&1, &2, joined))}
    else
      {:error, message} -> {{:error, message}, state}
    end
  end

  # The children that join on `node`, started as the job's first ones
  # were (`RingTracer.Job.Start`): the node checked, the scene sent if it
  # lacks it.
  defp start_joined(state, node, joined) do
    speeds = List.to_tuple(state.spec.speeds)
    plan = %{node => Enum.map(joined, &{&1, Spec.speed(speeds, &1)})}

    case RingTracer.Job.Start.run(state.spec, plan) do
      {:ok, started, bytes} ->
        node_bytes = Map.update(state.node_bytes, node, bytes[node], &(&1 + bytes[node]))
        {:ok, %{state | node_bytes: node_bytes}, started}

      {:error, _reason, message, started} ->
        for {_, pid} <- started, do: Process.exit(pid, :kill)
        {:error, {:node_unavailable, "could not prepare #{node}: #{message}"}}
    end
  end

  # The liveness watch, on a node the job had not used.
  defp watch(state, node) do
    if MapSet.member?(state.watched, node) do
      state
    else
      _ = RingTracer.Cluster.Liveness.start([node], state.spec.liveness)
      %{state | watched: MapSet.put(state.watched, node)}
    end
  end

  # The new children into the ring: published on every node, linked after
  # the highest living child, the lowest one's left sibling now the
  # highest new one, everybody told the ring's new size.
  defp splice(state, node, started) do
    old = state.children |> Map.keys() |> Enum.sort()
    joined = Enum.map(started, &elem(&1, 0))

    state = %{
      state
      | children: Map.merge(state.children, Map.new(started)),
        pids: Map.merge(state.pids, Map.new(started)),
        monitors:
          Map.merge(
            state.monitors,
            Map.new(started, fn {i, pid} -> {Process.monitor(pid), i} end)
          ),
        placement: Map.merge(state.placement, Map.new(joined, &{&1, node})),
        size: state.size + length(started)
    }

    publish(state)
    lefts = RingTracer.Job.Elastic.lefts(old, joined)

    state =
      Enum.reduce(joined, state, fn i, st ->
        left = Map.fetch!(lefts, i)
        ring = %{left: Map.fetch!(st.pids, left), left_index: left, size: st.size, t0: st.t0}
        send_counted(st, Map.fetch!(st.children, i), :control, {:ring, ring})
      end)

    Enum.reduce(old, state, fn i, st ->
      {left, left_index} =
        case lefts do
          %{^i => left} -> {Map.fetch!(st.pids, left), left}
          _ -> {nil, nil}
        end

      ring = %{left: left, left_index: left_index, size: st.size, joined: joined}
      send_counted(st, Map.fetch!(st.children, i), :control, {:ring_grown, ring})
    end)
  end

  # The living children on `node` leave: each gets the stop message,
  # reports and stops; its atoms are handed out again when it is gone, as
  # a dead child's (`child_lost/3`).
  defp shrink(state, node) do
    leaving =
      for {i, pid} <- Enum.sort(state.children),
          Map.fetch!(state.placement, i) == node,
          not MapSet.member?(state.leaving, i),
          do: {i, pid}

    staying =
      Enum.count(state.children, fn {i, _} -> not MapSet.member?(state.leaving, i) end) -
        length(leaving)

    if leaving != [] and staying <= 0,
      do:
        {{:error,
          {:invalid_option,
           "every remaining child of the job is on #{node}: none would stay (cancel the job instead)"}},
         state},
      else: leave(state, node, leaving)
  end

  defp leave(state, node, leaving) do
    state =
      Enum.reduce(leaving, state, fn {_i, pid}, st ->
        send_counted(st, pid, :control, {:stop, self()})
      end)

    indices = Enum.map(leaving, &elem(&1, 0))

    if indices != [] do
      RingTracer.Telemetry.execute(
        [:ring_tracer, :job, :shrunk],
        %{children: length(indices), system_time: System.system_time()},
        %{job: state.spec.id, node: node, leaving: indices}
      )
    end

    {{:ok, indices}, %{state | leaving: MapSet.union(state.leaving, MapSet.new(indices))}}
  end

  ## Frames

  # Coverage.add/2, where an atom of a frame already complete (and
  # forgotten) is a duplicate too.
  defp add(state, atom) do
    if frame_done?(state, Layout.frame(state.spec.layout, atom)),
      do: {:duplicate, state.coverage},
      else: Coverage.add(state.coverage, atom)
  end

  defp frame_done?(state, f), do: f < state.low or MapSet.member?(state.done_above, f)

  # Whether atom or piece `a` needs tracing no more.
  defp covered?(state, a),
    do:
      frame_done?(state, Layout.frame(state.spec.layout, a)) or
        Coverage.covered?(state.coverage, a)

  defp new_frame(state, f) do
    now = Child.job_time(state)

    frame = %{
      results: %{},
      tinted: %{},
      missing: Layout.frame_atom_count(state.spec.layout),
      released_us: now,
      traced: %{},
      rays: RingTracer.Rays.zero()
    }

    if state.spec.layout.frames > 1 or state.spec.sequence do
      RingTracer.Telemetry.execute(
        [:ring_tracer, :frame, :start],
        %{at_us: now},
        %{job: state.spec.id, frame: Enum.at(state.spec.frames, f) + 1}
      )
    end

    %{state | frames: Map.put(state.frames, f, frame), released: max(state.released, f + 1)}
  end

  # Releases frames while the window has room (the first one was released
  # with the initial atoms).
  defp release(%{spec: %Spec{layout: layout, window: window}, released: r, kept: kept} = state)
       when r < layout.frames and r < kept + window do
    state
    |> new_frame(r)
    |> run_strategy(&state.strategy.parent_frame(&1, &2, r))
    |> release()
  end

  defp release(state), do: state

  # Frame `f` is complete. In a sequence it goes now to whoever gets the
  # job's progress (the caller, if nobody), and the parent forgets it;
  # otherwise (one image) it is kept for the end.
  defp frame_done(%{spec: %Spec{sequence: false}} = state, _f), do: state

  defp frame_done(state, f) do
    %Spec{layout: layout, frames: numbers, id: id, caller: caller, progress: to} = state.spec
    {frame, frames} = Map.pop(state.frames, f)
    atoms = Layout.frame_atoms(layout, f)

    result = %RingTracer.Frame{
      number: Enum.at(numbers, f) + 1,
      width: layout.width,
      height: layout.height,
      pixels: assemble(layout, frame.results, f, state.spec.pixels),
      pixel_format: state.spec.pixels,
      released_us: frame.released_us,
      completed_us: Child.job_time(state),
      atoms: Range.size(atoms),
      traced: frame.traced,
      rays: frame.rays
    }

    RingTracer.Telemetry.execute(
      [:ring_tracer, :frame, :stop],
      %{at_us: result.completed_us, elapsed_us: RingTracer.Frame.elapsed_us(result)},
      %{job: id, frame: result}
    )

    send(to || caller, {@reply_tag, id, {:frame, result.number, result}})

    traced_by = Map.drop(state.traced_by, Map.keys(frame.results))
    coverage = Map.drop(state.coverage, Enum.to_list(atoms))
    {low, done_above} = advance(state.low, MapSet.put(state.done_above, f))

    state = if state.spec.ack, do: state, else: acked(state, f)

    %{
      state
      | frames: frames,
        traced_by: traced_by,
        coverage: coverage,
        ledger: Ledger.drop(state.ledger, atoms),
        low: low,
        done_above: done_above,
        summaries: [RingTracer.Frame.summary(result) | state.summaries]
    }
    |> release()
  end

  # The caller is done with frame `f`: it leaves the window.
  defp acked(state, f) do
    {kept, kept_above} = advance(state.kept, MapSet.put(state.kept_above, f))
    %{state | kept: kept, kept_above: kept_above}
  end

  defp advance(low, done) do
    if MapSet.member?(done, low),
      do: advance(low + 1, MapSet.delete(done, low)),
      else: {low, done}
  end

  # What a preview sees of the job's pixels: the oldest frame in flight's.
  defp oldest_results(state) do
    case Map.get(state.frames, state.low) do
      nil -> %{}
      frame -> frame.results
    end
  end

  defp down(state, ref, reason) do
    case Map.pop(state.monitors, ref) do
      {nil, _} ->
        # The caller went away: nobody wants the image.
        if state.stopping, do: {:noreply, state}, else: cancel(state)

      {index, monitors} ->
        state = %{state | monitors: monitors}

        cond do
          state.stopping != nil and monitors == %{} -> finish(state)
          state.stopping != nil -> {:noreply, state}
          true -> child_lost(state, index, reason)
        end
    end
  end

  # A child (or its whole node) is gone. The atoms it may have held are
  # handed out again at once (`RingTracer.Job.Ledger`); the ring is
  # re-linked around the gap and every child is told (a child whose offer
  # went to the dead sibling sends a fresh one: the lost token is
  # regenerated).
  defp child_lost(state, index, reason) do
    children = Map.delete(state.children, index)

    failure = %{
      child: index,
      reason: inspect(reason),
      at_us: System.monotonic_time(:microsecond) - state.started
    }

    # What it may hold, and what it gave that may have been lost on the way
    # with its node.
    lost = Enum.uniq(Ledger.held(state.ledger, index) ++ Ledger.in_transit(state.ledger, index))

    state = %{
      state
      | children: children,
        dead: Map.put(state.dead, index, failure),
        ledger: Ledger.forget(state.ledger, index)
    }

    cond do
      children == %{} ->
        fail(state, "every child exited; the last, child #{index}: #{inspect(reason)}")

      state.relinking ->
        {:noreply, reassign(state, lost)}

      true ->
        # Deaths already in the mailbox (a node's children die together)
        # are marked before this message arrives: one round of news for all.
        send(self(), :relink)
        {:noreply, reassign(%{state | relinking: true}, lost)}
    end
  end

  defp relink(state) do
    live = state.children |> Map.keys() |> Enum.sort()
    lefts = Enum.zip(live, [List.last(live) | Enum.drop(live, -1)])

    Enum.reduce(lefts, state, fn {i, left}, st ->
      ring = %{left: Map.fetch!(st.children, left), left_index: left, dead: Map.keys(st.dead)}
      send_counted(st, Map.fetch!(st.children, i), :control, {:ring_changed, ring})
    end)
  end

  # Atoms lost with a child, less those traced since, to the live children
  # in shares that follow their speeds.
  defp reassign(state, atoms) do
    case Enum.reject(atoms, &covered?(state, &1)) do
      [] -> state
      lost -> state |> spread(lost) |> Map.update!(:redone, &(&1 + length(lost)))
    end
  end

  # Atoms to the live children in shares that follow their speeds.
  defp spread(state, atoms) do
    atoms
    |> shares(weights(state))
    |> Enum.reduce(state, fn {i, share}, st -> hand_out(st, i, share) end)
  end

  # What each live child has traced so far (plus one, so that a child yet to
  # trace an atom still gets a share): a measure of its speed.
  defp weights(state) do
    for i <- state.children |> Map.keys() |> Enum.sort(),
        do: {i, Map.get(state.traced_counts, i, 0) + 1}
  end

  @doc """
  `atoms` split into consecutive shares, one per child of `weights`
  (`{index, weight}`), each in proportion to its weight (largest
  remainders); children whose share is empty are left out.

      iex> RingTracer.Job.Parent.shares(Enum.to_list(1..10), [{0, 3}, {2, 1}, {5, 1}])
      [{0, [1, 2, 3, 4, 5, 6]}, {2, [7, 8]}, {5, [9, 10]}]
      iex> RingTracer.Job.Parent.shares([7], [{0, 1}, {1, 1}])
      [{0, [7]}]
  """
  @spec shares([Layout.atom_id()], [{non_neg_integer(), pos_integer()}]) ::
          [{non_neg_integer(), [Layout.atom_id()]}]
  def shares(atoms, weights) do
    n = length(atoms)
    total = weights |> Enum.map(&elem(&1, 1)) |> Enum.sum()
    exact = Enum.map(weights, fn {i, w} -> {i, n * w / total} end)
    floors = Enum.map(exact, fn {i, x} -> {i, trunc(x)} end)
    short = n - Enum.sum(Enum.map(floors, &elem(&1, 1)))

    extra =
      exact
      |> Enum.sort_by(fn {i, x} -> {x - trunc(x), -i} end, :desc)
      |> Enum.take(short)
      |> MapSet.new(&elem(&1, 0))

    floors
    |> Enum.map(fn {i, k} -> {i, if(MapSet.member?(extra, i), do: k + 1, else: k)} end)
    |> Enum.map_reduce(atoms, fn {i, k}, rest ->
      {mine, rest} = Enum.split(rest, k)
      {{i, mine}, rest}
    end)
    |> elem(0)
    |> Enum.reject(&(elem(&1, 1) == []))
  end

  defp child_node(pid) when is_pid(pid), do: node(pid)
  defp child_node(_), do: nil

  defp atom_event(state, child, atom, pixels, rays, us) do
    total = Layout.atom_count(state.spec.layout)

    RingTracer.Telemetry.execute(
      [:ring_tracer, :atom, :stop],
      %{rays: RingTracer.Rays.total(rays), trace_us: us},
      %{
        job: state.spec.id,
        atom: atom,
        child: child,
        node: child_node(state.children[child]),
        done: total - state.missing,
        total: total,
        pixels: pixels
      }
    )
  end

  # Progress goes to the caller about a thousand times a job at most (every
  # atom when there are fewer), and always when the last atom arrives: a
  # message per atom would cost the caller as much as the atom at a million
  # atoms.
  defp progress(%{spec: %Spec{progress: nil}} = state), do: state

  defp progress(%{spec: spec} = state) do
    total = Layout.atom_count(spec.layout)
    done = total - state.missing

    if done == total or done - state.reported >= max(div(total, 1000), 1) do
      send(spec.progress, {@reply_tag, spec.id, {:progress, done, total}})
      %{state | reported: done}
    else
      state
    end
  end

  defp stop_children(state),
    do: stopping(%{state | completed: System.monotonic_time(:microsecond)}, :ok)

  defp fail(state, message), do: stopping(state, {:error, message})

  defp stopping(state, outcome) do
    state =
      Enum.reduce(state.children, state, fn {_i, pid}, st ->
        send_counted(st, pid, :control, {:stop, self()})
      end)

    state = %{state | stopping: %{outcome: outcome, reports: %{}}}
    if state.monitors == %{}, do: finish(state), else: {:noreply, state}
  end

  defp cancel(state) do
    for {_i, pid} <- state.children, do: Process.exit(pid, :kill)
    {:stop, :normal, state}
  end

  # `nodes` is one node per child (`RingTracer.Options` places them), or []
  # when every child runs on this node.
  defp placement([], n), do: List.duplicate(node(), n)
  defp placement(nodes, n) when length(nodes) == n, do: nodes

  defp node_summary(state, reports) do
    0..(state.size - 1)
    |> Enum.map(&Map.fetch!(state.placement, &1))
    |> Enum.zip(reports)
    |> Enum.group_by(&elem(&1, 0), &elem(&1, 1))
    |> Map.new(fn {node, rs} ->
      {node,
       %{
         children: length(rs),
         traced: Enum.sum(Enum.map(rs, & &1.stats.traced)),
         scene_bytes: Map.get(state.node_bytes, node, 0)
       }}
    end)
  end

  defp dead_report(i, failure) do
    stats = %{RingTracer.Job.Stats.new(i, nil, 1, 0) | failed: failure.reason}
    %{stats: stats, traffic: %{}, events: [], atoms: []}
  end

  # One record per atom or piece: the copy whose pixels the parent kept.
  # In image order (by first pixel; the atom's name breaks ties), by one
  # stable key sort, after which the copies of one atom are neighbours and
  # the first is kept: a million atoms take a fraction of a second.
  defp kept_atoms(reports, traced_by, layout) do
    reports
    |> Enum.flat_map(fn report ->
      for %{atom: atom, child: child} = record <- report.atoms,
          Map.get(traced_by, atom) == child,
          do: {{Layout.span(layout, atom), atom}, record}
    end)
    |> then(&:lists.keysort(1, &1))
    |> first_copies(nil, [])
  end

  defp first_copies([], _last, acc), do: Enum.reverse(acc)
  defp first_copies([{key, _} | rest], key, acc), do: first_copies(rest, key, acc)

  defp first_copies([{key, record} | rest], _last, acc),
    do: first_copies(rest, key, [record | acc])

  @doc """
  The image of frame `frame` (the first by default) from the pixels
  received of it, by atom or piece (`results`, in `format`, a
  `RingTracer.Pixels` format, `:float` by default): each atom's pieces in
  pixel order, the pixels two pieces share (after a failure) taken once.

      iex> layout = RingTracer.Layout.new(4, 1, 1, 1)
      iex> {h, t} = RingTracer.Layout.split(0, 1, 2)
      iex> px = fn n -> :binary.copy(<<n::96>>, 1) end
      iex> results = %{t => px.(3) <> px.(4), h => px.(1) <> px.(2), {0, 1, 3, 4} => px.(2) <> px.(3)}
      iex> RingTracer.Job.Parent.assemble(layout, results) == px.(1) <> px.(2) <> px.(3) <> px.(4)
      true
  """
  @spec assemble(
          Layout.t(),
          %{Layout.atom_id() => binary()},
          non_neg_integer(),
          RingTracer.Pixels.format()
        ) :: binary()
  def assemble(layout, results, frame \\ 0, format \\ :float) do
    whole =
      if map_size(results) == Layout.frame_atom_count(layout),
        do: whole_atoms(layout, results, frame)

    whole || assemble_pieces(layout, results, frame, RingTracer.Pixels.bytes_per_pixel(format))
  end

  # Every atom came back whole (as many results as atoms, each an atom's):
  # the image is their pixels in atom order.
  defp whole_atoms(layout, results, frame) do
    layout
    |> Layout.frame_atoms(frame)
    |> Enum.reduce_while([], fn a, acc ->
      case results do
        %{^a => pixels} -> {:cont, [pixels | acc]}
        _ -> {:halt, nil}
      end
    end)
    |> case do
      nil -> nil
      reversed -> reversed |> Enum.reverse() |> IO.iodata_to_binary()
    end
  end

  defp assemble_pieces(layout, results, frame, bpp) do
    by_atom = Enum.group_by(results, fn {a, _} -> Layout.base(a) end)

    layout
    |> Layout.frame_atoms(frame)
    |> Enum.map(fn a ->
      {first, _} = Layout.span(layout, a)

      by_atom
      |> Map.fetch!(a)
      |> Enum.map(fn {piece, pixels} -> {Layout.span(layout, piece), pixels} end)
      |> Enum.sort()
      |> Enum.reduce({first, []}, fn {{f, c}, pixels}, {cursor, acc} ->
        if f + c > cursor,
          do: {f + c, [binary_part(pixels, (cursor - f) * bpp, (f + c - cursor) * bpp) | acc]},
          else: {cursor, acc}
      end)
      |> elem(1)
      |> Enum.reverse()
    end)
    |> IO.iodata_to_binary()
  end

  defp finish(state) do
    %{spec: spec, stopping: stopping} = state
    now = System.monotonic_time(:microsecond)

    reply =
      case stopping.outcome do
        :ok -> {:ok, success(state, final_reports(state), now)}
        {:error, message} -> {:error, message}
      end

    stop_helpers(state.helpers)

    RingTracer.Telemetry.execute(
      [:ring_tracer, :job, :stop],
      %{duration: System.convert_time_unit(now - state.started, :microsecond, :native)},
      %{job: spec.id, outcome: elem(reply, 0), reply: reply}
    )

    send(spec.caller, {@reply_tag, spec.id, reply})
    {:stop, :normal, state}
  end

  # Every child's report, by index: as it stopped, as it left, or as it
  # died. A child that died after the image was complete, before it
  # reported, costs its statistics, not the image.
  defp final_reports(state) do
    for i <- 0..(state.size - 1) do
      case {state.departed, state.dead, state.stopping.reports} do
        {%{^i => report}, _, _} -> report
        {_, %{^i => failure}, _} -> dead_report(i, failure)
        {_, _, %{^i => report}} -> report
        _ -> dead_report(i, %{reason: "exited before reporting its statistics"})
      end
    end
  end

  # The reply of a job that completed (`t:reply/0`).
  defp success(state, reports, now) do
    %{spec: spec} = state
    first = state.frames[0]

    traffic =
      Enum.reduce(reports, state.traffic, fn r, acc ->
        Map.merge(acc, r.traffic, fn _, {n1, b1}, {n2, b2} -> {n1 + n2, b1 + b2} end)
      end)

    %{
      pixels:
        if(spec.sequence, do: nil, else: assemble(spec.layout, first.results, 0, spec.pixels)),
      pixel_format: spec.pixels,
      tinted:
        if(spec.tint and not spec.sequence,
          do: assemble(spec.layout, first.tinted, 0, :srgb8)
        ),
      frames: Enum.reverse(state.summaries),
      kept_trace_us: state.kept_trace_us,
      started_at_us: state.t0,
      # The makespan ends when the image is complete; stopping the children
      # and collecting their reports afterwards is reported apart.
      elapsed_us: state.completed - state.started,
      teardown_us: now - state.completed,
      children: Enum.map(reports, & &1.stats),
      atoms: kept_atoms(reports, state.traced_by, spec.layout),
      events: reports |> Enum.flat_map(& &1.events) |> Enum.sort_by(& &1.at_us),
      traffic: traffic,
      duplicates: state.duplicates,
      failures:
        state.dead
        |> Map.drop(MapSet.to_list(state.leaving))
        |> Map.values()
        |> Enum.sort_by(& &1.child),
      redone: state.redone,
      nodes: node_summary(state, reports),
      layout: spec.layout.order
    }
  end

  defp stop_helpers(helpers) do
    for {pid, ref} <- helpers do
      Process.exit(pid, :kill)

      receive do
        {:DOWN, ^ref, _, _, _} -> :ok
      end
    end
  end
end
