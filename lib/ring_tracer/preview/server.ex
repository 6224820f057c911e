defmodule RingTracer.Preview.Server do
  @moduledoc false
  # The process behind one preview (`RingTracer.Preview`): it owns the HTTP
  # server (OTP's `:httpd`, started stand-alone for this preview, with
  # `RingTracer.Preview.HTTP` as its only module) and the job's event log
  # (`RingTracer.Preview.Log`), kept in a protected ETS table that viewers
  # read from, frame by frame.
  #
  # It learns about its job from `RingTracer.Telemetry` handlers (atoms,
  # hand-overs and a sequence's frames released and complete from the
  # parent, which runs on this node; help offers from each child's node) and
  # from the parent's description of the job
  # (`RingTracer.Job.Parent.describe/2`), which carries the atoms traced
  # before the preview opened. A handler only sends this process a message:
  # the job never waits for the preview, nor for any viewer. While the job
  # runs, the server spends at most `:cpu_share` of one core on atoms (0.01
  # by default: the job's events wait in a queue that pauses 99 times as
  # long as the atoms' CPU time, in pauses of at least 20 ms, until the job
  # ends, while the server answers everything else; `RingTracer.Preview.Pacing`),
  # and it and the viewers run at low process priority. Of a
  # sequence, the queue keeps only what the log would keep: when a frame
  # completes, the queued atoms of the frames complete before it are dropped
  # (but the highest complete's), and only the `strip` highest numbers
  # complete keep their pixels for a thumbnail (`RingTracer.Preview.Backlog`);
  # the log's frames the sequence no longer needs are deleted from the table.
  use GenServer

  alias RingTracer.Preview.{Backlog, Listener, Log, Pacing}

  # How long a viewer's connection may take no data, during a stop, before
  # it is dropped.
  @stall_ms 100
  # Connections without a stream kept at most (the oldest beyond are
  # dropped, each @sweep_ms), and httpd's backstop beyond the viewers.
  @max_waiting 64
  @sweep_ms 100
  @max_connections 1024

  @enforce_keys [:table, :server, :port, :addr, :token, :log, :max_viewers, :ended, :cpu_share]
  defstruct @enforce_keys ++
              [
                owner: nil,
                last_atom: nil,
                last_image: nil,
                parent: nil,
                handlers: [],
                waiters: MapSet.new(),
                viewers: %{},
                expect: nil,
                pending: [],
                queue: :queue.new(),
                pacing: nil,
                debt_us: 0,
                drain: nil,
                waiting: %{}
              ]

  @typedoc """
  The preview's state: its event table and HTTP server (address, port,
  token), the job's log, who owns the preview (it stops with them), the
  job's last atom and image seen, the job's parent and the telemetry
  handlers attached for it, viewers waiting for more and those streaming
  (at most `max_viewers`), the job expected (`expect`) and the events that
  came before it was known (`pending`), the queue of atoms waiting for
  their share of CPU (`cpu_share`), its pacing timer and the work done
  since its last pause (`debt_us`, `RingTracer.Preview.Pacing`), a stop's drain,
  the connections without a stream yet (`waiting`), and `ended`, an
  atomics the request processes read.
  """
  @type t :: %__MODULE__{
          table: :ets.tid(),
          server: Listener.t(),
          port: :inet.port_number(),
          addr: :inet.ip_address(),
          token: String.t(),
          log: Log.t(),
          owner: pid() | nil,
          last_atom: term(),
          last_image: term(),
          parent: pid() | nil,
          handlers: [term()],
          waiters: MapSet.t(pid()),
          viewers: %{pid() => term()},
          max_viewers: pos_integer(),
          expect: term(),
          ended: :atomics.atomics_ref(),
          cpu_share: float(),
          pending: [term()],
          queue: :queue.queue(),
          pacing: {reference(), reference()} | nil,
          debt_us: non_neg_integer(),
          drain: term(),
          waiting: %{pid() => term()}
        }

  @doc false
  @spec start(keyword()) :: GenServer.on_start()
  def start(opts), do: GenServer.start(__MODULE__, opts)

  @impl GenServer
  def init(opts) do
    Process.flag(:trap_exit, true)
    Process.flag(:message_queue_data, :off_heap)
    # The job's processes come first on a scheduler: the preview runs when
    # they wait.
    Process.flag(:priority, :low)
    table = :ets.new(__MODULE__, [:ordered_set, :protected, read_concurrency: true])
    addr = Keyword.get(opts, :listen, {127, 0, 0, 1})
    max_viewers = Keyword.get(opts, :max_viewers, 32)
    # The page's address holds a random path: another local user (anyone
    # can reach loopback) or a web page that rebinds a name of its own to
    # 127.0.0.1 cannot guess it, and only sees 404s.
    token = Listener.token()
    secret = Listener.secret(token, addr)

    listen = [
      listen: addr,
      port: Keyword.get(opts, :port, 0),
      name: ~c"ringtracer-preview",
      root: RingTracer.Preview.HTTP.root(),
      # Viewers are counted by this server (`:max_viewers`); httpd's limit is
      # only a backstop: the connections without a stream are kept to
      # @max_waiting by the sweep, which drops the oldest first.
      max_clients: max_viewers + @max_connections
    ]

    case Listener.start(RingTracer.Preview.HTTP, {self(), table, secret}, listen) do
      {:ok, server} ->
        state = %__MODULE__{
          table: table,
          server: server,
          port: server.port,
          addr: addr,
          token: token,
          log: Log.new(Keyword.take(opts, [:max_events, :strip])),
          max_viewers: max_viewers,
          ended: :atomics.new(1, []),
          cpu_share: Keyword.get(opts, :cpu_share, 0.01)
        }

        Process.send_after(self(), :sweep, @sweep_ms)
        {:ok, state}

      {:error, {:listen, reason}} ->
        {:stop, {:listen, reason}}
    end
  end

  @impl GenServer
  def handle_call(:address, _from, state),
    do: {:reply, {state.addr, state.port, state.token}, state}

  def handle_call(:viewers, _from, state), do: {:reply, map_size(state.viewers), state}

  # A viewer's request process, with its socket: one more viewer unless
  # there are already `:max_viewers`.
  def handle_call({:viewer, pid, socket}, _from, state) do
    if map_size(state.viewers) >= state.max_viewers do
      {:reply, {:error, :full}, state}
    else
      viewer = %{ref: Process.monitor(pid), socket: socket, queued: 0, sent: nil}
      {:reply, :ok, %{state | viewers: Map.put(state.viewers, pid, viewer)}}
    end
  end

  def handle_call({:expect, _id, _nodes}, _from, %{expect: e} = state) when e != nil,
    do: {:reply, {:error, :already_watching}, state}

  # Before the job's parent starts (render/2's :preview): the handlers are
  # in place from the job's first event.
  def handle_call({:expect, id, nodes}, _from, state),
    do: {:reply, :ok, %{attach_all(state, id, nodes) | expect: id}}

  def handle_call({:watch, _parent, _progress}, _from, %{parent: p} = state) when p != nil,
    do: {:reply, {:error, :already_watching}, state}

  def handle_call({:watch, parent, progress}, _from, state) do
    state = if state.expect, do: state, else: attach_all(state, nil, [])
    {reply, state} = watched(state, parent, describe(parent, progress))
    {:reply, reply, state}
  end

  @impl GenServer
  # render/2's :preview: its caller described the job's parent as soon as
  # it started. This server runs at low priority: a short job can end, and
  # its parent exit, before it runs (its events wait in `pending`).
  def handle_cast({:described, _parent, _described}, %{parent: p} = state) when p != nil,
    do: {:noreply, state}

  def handle_cast({:described, parent, described}, state),
    do: {:noreply, state |> watched(parent, described) |> elem(1)}

  # The job of `parent`, as `describe/2` gave it: the log starts.
  defp watched(state, parent, described) do
    # Expected (render/2's :preview): the handlers were there before the job.
    from_start = state.expect != nil

    case described do
      {:ok, info} when state.expect in [nil, info.id] ->
        info = Map.put(info, :from_start, from_start)
        Process.monitor(parent)
        # Opened on a running job: now its other nodes are known.
        state =
          if state.expect, do: state, else: attach_all(state, info.id, info.nodes -- [node()])

        state = update(%{state | parent: parent, expect: info.id}, &Log.job(&1, info))
        pending = Enum.reverse(state.pending)
        state = Enum.reduce(pending, %{state | pending: []}, &apply_event(&2, &1))
        {:ok, state}

      {:ok, _other} ->
        {{:error, :other_job}, state}

      other ->
        state = if state.expect, do: state, else: detach_all(state)
        {other, state}
    end
  end

  # The expected job's start, from its parent: the same description, which
  # the render's caller may have failed to get if the job had already ended.
  @impl GenServer
  def handle_info({:job_start, parent, job, info}, %{parent: nil, expect: job} = state),
    do: {:noreply, state |> watched(parent, {:ok, info}) |> elem(1)}

  def handle_info({:job_start, _parent, _job, _info}, state), do: {:noreply, state}

  def handle_info({kind, job, a, _, _, _, _, _} = msg, %{log: %{job: nil}, expect: job} = state)
      when kind == :atom,
      do: {:noreply, %{state | pending: [msg | state.pending], last_atom: a}}

  def handle_info({kind, job, _, _, _, _} = msg, %{log: %{job: nil}, expect: job} = state)
      when kind in [:moved, :child_event],
      do: {:noreply, %{state | pending: [msg | state.pending]}}

  def handle_info({:job_stop, job, _} = msg, %{log: %{job: nil}, expect: job} = state),
    do: {:noreply, %{state | pending: [msg | state.pending]}}

  def handle_info({kind, job, a, _, _, _, _, _} = msg, %{log: %{job: job}} = state)
      when kind == :atom,
      do: {:noreply, enqueue(%{state | last_atom: a}, msg)}

  # A sequence's images: released, and complete (after its last atom, the
  # last one received).
  def handle_info({:frame_start, job, _, _} = msg, %{log: %{job: nil}, expect: job} = state),
    do: {:noreply, %{state | pending: [msg | state.pending]}}

  def handle_info({:frame_start, job, _, _} = msg, %{log: %{job: job}} = state),
    do: {:noreply, enqueue(state, msg)}

  def handle_info({:frame_stop, job, _, _, _} = msg, %{log: %{job: nil}, expect: job} = state),
    do: {:noreply, %{state | pending: [image_done(msg, state.last_atom) | state.pending]}}

  def handle_info({:frame_stop, job, _, _, _} = msg, %{log: %{job: job}} = state) do
    msg = image_done(msg, state.last_atom)
    {queue, last_image} = Backlog.prune(state.queue, msg, state.last_image, state.log)
    {:noreply, enqueue(%{state | queue: queue, last_image: last_image}, msg)}
  end

  def handle_info({kind, job, _, _, _, _} = msg, %{log: %{job: job}} = state)
      when kind in [:moved, :child_event],
      do: {:noreply, enqueue(state, msg)}

  def handle_info({:job_stop, job, _} = msg, %{log: %{job: job}} = state),
    do: {:noreply, enqueue(state, msg)}

  def handle_info({:pace, ref}, %{pacing: {ref, _}} = state),
    do: {:noreply, run_queue(%{state | pacing: nil})}

  # The job is over: what is queued goes to the log first.
  def handle_info({:DOWN, _, :process, parent, reason}, %{parent: parent} = state) do
    :atomics.put(state.ended, 1, 1)
    {:noreply, enqueue(state, {:gone, reason})}
  end

  def handle_info({:wait, pid, cursor}, state) do
    if state.log.seq > cursor do
      send(pid, :preview_more)
      {:noreply, state}
    else
      {:noreply, %{state | waiters: MapSet.put(state.waiters, pid)}}
    end
  end

  def handle_info({:owner, pid}, state) do
    Process.monitor(pid)
    {:noreply, %{state | owner: pid}}
  end

  def handle_info({:DOWN, _, :process, pid, _}, %{owner: pid} = state),
    do: {:stop, :normal, state}

  def handle_info({:viewer_done, pid}, state) do
    {viewer, viewers} = Map.pop(state.viewers, pid)
    if viewer, do: Process.demonitor(viewer.ref, [:flush])
    {:noreply, drained(%{state | viewers: viewers})}
  end

  def handle_info({:DOWN, _, :process, pid, _}, state) when is_map_key(state.viewers, pid),
    do: {:noreply, drained(%{state | viewers: Map.delete(state.viewers, pid)})}

  def handle_info({:drain, from, ref, ms}, state) do
    timer = Process.send_after(self(), {:drain_timeout, ref}, ms)
    state = %{state | drain: {from, ref, timer}, viewers: sample(state.viewers)}
    if state.viewers != %{}, do: Process.send_after(self(), {:drain_check, ref}, @stall_ms)
    {:noreply, drained(state)}
  end

  # During a stop, a viewer whose connection has data waiting and took none
  # of it since the last look is not reading: it is dropped, not waited for.
  def handle_info({:drain_check, ref}, %{drain: {_, ref, _}} = state) do
    {stalled, reading} =
      state.viewers
      |> sample()
      |> Enum.split_with(fn {pid, v} -> stalled?(v, state.viewers[pid]) end)

    for {pid, v} <- stalled do
      Process.demonitor(v.ref, [:flush])
      Process.exit(pid, :kill)
    end

    Process.send_after(self(), {:drain_check, ref}, @stall_ms)
    {:noreply, drained(%{state | viewers: Map.new(reading)})}
  end

  def handle_info({:drain_timeout, ref}, %{drain: {from, ref, _}} = state) do
    send(from, {:drained, ref})
    {:noreply, %{state | drain: nil}}
  end

  def handle_info(:sweep, state) do
    Process.send_after(self(), :sweep, @sweep_ms)
    {:noreply, sweep(state)}
  end

  def handle_info(_other, state), do: {:noreply, state}

  # Connections that are not viewers are kept to @max_waiting, the oldest
  # dropped first (`Listener.sweep/4`).
  defp sweep(state),
    do: %{
      state
      | waiting: Listener.sweep(state.server, state.waiting, state.viewers, @max_waiting)
    }

  # A stop waits for the viewers still reading the log.
  defp drained(%{drain: {from, ref, timer}, viewers: v} = state) when map_size(v) == 0 do
    Process.cancel_timer(timer)
    send(from, {:drained, ref})
    %{state | drain: nil}
  end

  defp drained(state), do: state

  # Each viewer's bytes queued in the VM for its socket and bytes the socket
  # has taken so far.
  defp sample(viewers) do
    Map.new(viewers, fn {pid, v} ->
      queued =
        case :erlang.port_info(v.socket, :queue_size) do
          {:queue_size, n} -> n
          _ -> 0
        end

      sent =
        case :inet.getstat(v.socket, [:send_oct]) do
          {:ok, [send_oct: n]} -> n
          _ -> nil
        end

      {pid, %{v | queued: queued, sent: sent}}
    end)
  end

  defp stalled?(now, before), do: now.queued > 0 and now.sent == before.sent

  @impl GenServer
  def terminate(_reason, state) do
    detach(state.handlers)
    # A viewer still connected is dropped at once: a stop never waits on a
    # browser (one that does not read would hold its connection's process in
    # a send until the send's deadline).
    Enum.each(Map.keys(state.viewers), &Process.exit(&1, :kill))
    Listener.close(state.server)
  end

  defp apply_event(state, {:atom, _job, a, child, pixels, rays, us, at}),
    do: update(state, &Log.atom(&1, a, child, pixels, rays, us, at))

  defp apply_event(state, {:moved, _job, from, to, n, at}),
    do: update(state, &Log.move(&1, from, to, n, at))

  defp apply_event(state, {:child_event, _job, kind, from, to, at}),
    do: update(state, &Log.event(&1, kind, from, to, at))

  defp apply_event(state, {:frame_start, _job, number, at}),
    do: update(state, &Log.release(&1, number, at))

  defp apply_event(state, {:image_done, _job, last, image}),
    do: update(state, &Log.image_done(&1, last, image))

  defp apply_event(state, {:job_stop, _job, reply}), do: update(state, &Log.final(&1, reply))
  defp apply_event(state, {:gone, reason}), do: update(state, &Log.gone(&1, reason))

  # While the job runs, the preview spends at most `cpu_share` of one core
  # on atoms (their pixels to sRGB and base64, and so what viewers send):
  # the job's events wait in a queue, in order, and once the atoms' work
  # since the last pause is worth a pause of `Pacing`'s quantum, the queue
  # pauses in proportion (a timer: meanwhile the server answers everything
  # else, a stop at once). When the job ends, the queue runs
  # through. On a render too light for the share, the page lags and catches
  # up at the end.
  defp enqueue(state, msg) do
    state = %{state | queue: :queue.in(msg, state.queue)}

    cond do
      state.pacing == nil ->
        run_queue(state)

      ended?(state) ->
        Process.cancel_timer(elem(state.pacing, 1))
        run_queue(%{state | pacing: nil})

      true ->
        state
    end
  end

  defp run_queue(state) do
    case :queue.out(state.queue) do
      {:empty, _} ->
        state

      {{:value, msg}, queue} when elem(msg, 0) in [:atom, :image_done] ->
        mark = Pacing.start()
        state = apply_event(%{state | queue: queue}, msg)
        debt = state.debt_us + Pacing.work_us(mark)

        case Pacing.pause(debt, state.cpu_share) do
          {:pause, wait_ms} when wait_ms > 0 ->
            if ended?(state) do
              run_queue(%{state | debt_us: 0})
            else
              ref = make_ref()
              timer = Process.send_after(self(), {:pace, ref}, wait_ms)
              %{state | pacing: {ref, timer}, debt_us: 0}
            end

          _ ->
            run_queue(%{state | debt_us: debt})
        end

      {{:value, msg}, queue} ->
        run_queue(apply_event(%{state | queue: queue}, msg))
    end
  end

  defp image_done({:frame_stop, job, frame, at, us}, last) do
    image = %{
      number: frame.number,
      width: frame.width,
      height: frame.height,
      pixels: frame.pixels,
      pixel_format: frame.pixel_format,
      at_us: at,
      elapsed_us: us
    }

    {:image_done, job, last, image}
  end

  defp ended?(state), do: :atomics.get(state.ended, 1) == 1

  # The parent's events (this node), and children's on `nodes` (filtered
  # there by job, when known).
  defp attach_all(state, job, nodes) do
    me = self()

    parent =
      if state.handlers == [] do
        [
          {[:ring_tracer, :job, :start], &RingTracer.Preview.Relay.job_start/4, me},
          {[:ring_tracer, :atom, :stop], &RingTracer.Preview.Relay.atom/4, me},
          {[:ring_tracer, :atoms, :moved], &RingTracer.Preview.Relay.moved/4, me},
          {[:ring_tracer, :frame, :start], &RingTracer.Preview.Relay.frame_start/4, me},
          {[:ring_tracer, :frame, :stop], &RingTracer.Preview.Relay.frame_stop/4, me},
          {[:ring_tracer, :job, :stop], &RingTracer.Preview.Relay.job_stop/4, {me, state.ended}}
        ]
        |> Enum.map(&attach(node(), &1))
      else
        []
      end

    children =
      for n <- Enum.uniq([node() | nodes]),
          not Enum.any?(state.handlers, &match?({^n, {_, _, [:ring_tracer, :child, :event]}}, &1)) do
        attach(
          n,
          {[:ring_tracer, :child, :event], &RingTracer.Preview.Relay.child_event/4, {me, job}}
        )
      end

    %{state | handlers: state.handlers ++ Enum.reject(parent ++ children, &is_nil/1)}
  end

  defp detach_all(state) do
    detach(state.handlers)
    %{state | handlers: []}
  end

  defp update(state, fun) do
    {frames, log} = Log.take(fun.(state.log))
    {forget, log} = Log.forget(log)
    # A sequence's frames it no longer needs (a viewer reading past one
    # just reads on: the table is ordered), those just appended included:
    # an image that completes after the strip's (a lower number, later)
    # leaves the strip as it enters it, and must not be stored.
    Enum.each(forget, &:ets.delete(state.table, &1))
    forgotten = MapSet.new(forget)
    frames = Enum.reject(frames, fn {seq, _} -> MapSet.member?(forgotten, seq) end)

    case frames do
      [] ->
        %{state | log: log}

      _ ->
        :ets.insert(
          state.table,
          for({seq, f} <- frames, do: {seq, f, seq == log.seq and log.done})
        )

        Enum.each(state.waiters, &send(&1, :preview_more))
        %{state | log: log, waiters: MapSet.new()}
    end
  end

  defp describe(parent, progress) do
    RingTracer.Job.Parent.describe(parent, progress)
  catch
    :exit, reason -> {:error, {:job_not_running, reason}}
  end

  defp attach(node, {event, fun, config}) do
    id = {__MODULE__, self(), event}

    result =
      if node == node(),
        do: RingTracer.Telemetry.attach(id, event, fun, config),
        else: :erpc.call(node, RingTracer.Telemetry, :attach, [id, event, fun, config], 5_000)

    if result == :ok, do: {node, id}, else: nil
  catch
    _, _ -> nil
  end

  defp detach(handlers) do
    for {node, id} <- Enum.reject(handlers, &is_nil/1) do
      try do
        if node == node(),
          do: RingTracer.Telemetry.detach(id),
          else: :erpc.call(node, RingTracer.Telemetry, :detach, [id], 2_000)
      catch
        _, _ -> :ok
      end
    end

    :ok
  end
end
