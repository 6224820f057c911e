defmodule RingTracer.Chaos.Pool do
  @moduledoc false
  # The chaos soak's peer nodes (`RingTracer.LocalCluster`, each a real OS
  # process on this machine), kept at a fixed count: a node that is killed,
  # that halts after a freeze, or that drops for any other reason is replaced
  # by a fresh one.
  #
  # Jobs `checkout/2` the nodes that are up (waiting, boundedly, until the
  # pool is at full strength) and say when they have `started/2`, that is,
  # when their parent has its ring running (its first atom came in). Node
  # faults wait until no job is starting on their node, so that every fault
  # lands on a running ring (a node lost while a parent is still starting its
  # children fails that job before any work, by design) and a node under a
  # pending fault is given to no new job.
  #
  #   * `kill/2` sends SIGKILL to the node's OS process: a crashed machine.
  #   * `freeze/3` sends SIGSTOP, and SIGCONT after the given time: a hung
  #     machine. Distribution's connection stays open, so only the jobs'
  #     liveness watch (`RingTracer.Cluster.Liveness`) notices; it disconnects
  #     the node, and a `:peer` node that loses its connection to this one
  #     halts when it runs again. A frozen node that nobody disconnected is
  #     back in service after SIGCONT.
  use GenServer

  alias RingTracer.LocalCluster

  @full_strength_wait 20_000

  @enforce_keys [:prefix, :log_level, :count]
  defstruct @enforce_keys ++
              [
                nodes: %{},
                starting: %{},
                boots: MapSet.new(),
                thaws: [],
                pending: [],
                waiting: [],
                started: 0,
                replaced: 0,
                unplanned: []
              ]

  @typedoc """
  The pool: how its nodes are named and log, how many it keeps, each
  node's peer, OS pid and status (`:up`, `:doomed` under a pending fault,
  `:frozen`, `:killed`), the jobs starting on each node, the processes
  booting a replacement and those that will resume a frozen node, the
  faults waiting for a node's jobs to start, the checkouts waiting for full
  strength, and the counts `stats/1` reports.
  """
  @type t :: %__MODULE__{
          prefix: String.t(),
          log_level: Logger.level(),
          count: non_neg_integer(),
          nodes: %{node() => %{peer: pid(), os_pid: String.t(), status: atom()}},
          starting: %{reference() => [node()]},
          boots: MapSet.t(pid()),
          thaws: [pid()],
          pending: [term()],
          waiting: [{reference(), GenServer.from(), reference()}],
          started: non_neg_integer(),
          replaced: non_neg_integer(),
          unplanned: [String.t()]
        }

  @typedoc "What `stats/1` returns."
  @type stats :: %{
          started: non_neg_integer(),
          replaced: non_neg_integer(),
          unplanned: [String.t()]
        }

  @doc """
  Starts the pool with `count` peer nodes and waits until they are up.
  Options: `:prefix`, how their names begin (default `"chaos"`), and
  `:log_level`, their logger's level (default `:error`: the soak makes
  nodes drop on purpose, and every peer would log it).
  """
  @spec start_link(non_neg_integer(), keyword()) :: GenServer.on_start()
  def start_link(count, opts \\ []) do
    prefix = Keyword.get(opts, :prefix, "chaos")
    GenServer.start_link(__MODULE__, {count, prefix, Keyword.get(opts, :log_level, :error)})
  end

  @doc """
  The nodes that are up, once every node is (or after 20 s, those that
  are), registered under a new reference as a job starting on them.
  """
  @spec checkout(GenServer.server()) :: {reference(), [node()]}
  def checkout(pool), do: GenServer.call(pool, :checkout, @full_strength_wait + 5_000)

  @doc "The job checked out as `ref` runs its ring (or has ended)."
  @spec started(GenServer.server(), reference()) :: :ok
  def started(pool, ref), do: GenServer.cast(pool, {:started, ref})

  @doc """
  Kills `node`'s OS process once no job is starting on it. Returns `:ok`,
  or `{:skipped, reason}` for a node that is not up.
  """
  @spec kill(GenServer.server(), node()) :: :ok | {:skipped, String.t()}
  def kill(pool, node), do: GenServer.call(pool, {:fault, :kill, node}, 60_000)

  @doc """
  Stops `node`'s OS process (SIGSTOP) once no job is starting on it, and
  resumes it (SIGCONT) `ms` milliseconds later. Returns as soon as the node
  is stopped: `:ok`, or `{:skipped, reason}`.
  """
  @spec freeze(GenServer.server(), node(), pos_integer()) :: :ok | {:skipped, String.t()}
  def freeze(pool, node, ms), do: GenServer.call(pool, {:fault, {:freeze, ms}, node}, 60_000)

  @doc "The nodes that are up now: not frozen, killed, or under a pending fault."
  @spec up(GenServer.server()) :: [node()]
  def up(pool), do: GenServer.call(pool, :up)

  @doc """
  Nodes started in all (the first ones included), nodes replaced, and the
  nodes that dropped without a fault of the pool's (e.g. disconnected by a
  liveness watch that took load for a freeze), each with its state then and
  how long it had been up.
  """
  @spec stats(GenServer.server()) :: stats()
  def stats(pool), do: GenServer.call(pool, :stats)

  @doc "Stops every peer node (resuming frozen ones first) and the pool."
  @spec stop(GenServer.server()) :: :ok
  def stop(pool), do: GenServer.stop(pool, :normal, 120_000)

  ## GenServer

  @impl GenServer
  def init({count, prefix, log_level}) do
    Process.flag(:trap_exit, true)
    # A peer's output goes to its starter's group leader; under capture_io
    # that is a StringIO, which a booting VM cannot set to binary mode.
    Process.group_leader(self(), Process.whereis(:user))
    LocalCluster.ensure_distributed()

    state = %__MODULE__{prefix: prefix, log_level: log_level, count: count}

    # The first nodes boot one after the other: on a small machine several
    # VMs booting at once can each take longer than :peer's boot timeout.
    state = Enum.reduce(1..count//1, state, fn _, st -> add(st, boot_now(prefix, log_level)) end)
    {:ok, state}
  end

  @impl GenServer
  def handle_call(:checkout, from, state) do
    ref = make_ref()

    if length(up_nodes(state)) >= state.count do
      {:reply, {ref, up_nodes(state)}, register(state, ref)}
    else
      timer = Process.send_after(self(), {:checkout_timeout, ref}, @full_strength_wait)
      {:noreply, %{state | waiting: state.waiting ++ [{ref, from, timer}]}}
    end
  end

  def handle_call({:fault, fault, node}, from, state) do
    case state.nodes do
      %{^node => %{status: :up} = info} ->
        state = put_in(state.nodes[node], %{info | status: :doomed})
        {:noreply, run_pending(%{state | pending: state.pending ++ [{from, fault, node}]})}

      _ ->
        {:reply, {:skipped, "#{node} is not up"}, state}
    end
  end

  def handle_call(:up, _from, state), do: {:reply, up_nodes(state), state}

  def handle_call(:stats, _from, state) do
    {:reply,
     %{
       started: state.started,
       replaced: state.replaced,
       unplanned: Enum.reverse(state.unplanned)
     }, state}
  end

  @impl GenServer
  def handle_cast({:started, ref}, state) do
    {:noreply, run_pending(%{state | starting: Map.delete(state.starting, ref)})}
  end

  @impl GenServer
  def handle_info({:booted, pid, {:ok, peer, node, os_pid}}, state) do
    state = %{state | boots: MapSet.delete(state.boots, pid)}
    {:noreply, serve_waiting(add(state, {:ok, peer, node, os_pid}))}
  end

  def handle_info({:booted, pid, {:error, _reason}}, state) do
    # Try again a second later: the pool is kept at its size.
    Process.send_after(self(), :boot, 1_000)
    {:noreply, %{state | boots: MapSet.delete(state.boots, pid)}}
  end

  def handle_info(:boot, state), do: {:noreply, boot(state)}

  def handle_info({:nodedown, node}, state) do
    case Map.pop(state.nodes, node) do
      {nil, _} ->
        {:noreply, state}

      {info, nodes} ->
        # Whatever was left of it goes (a frozen node may still be stopped).
        signal(info.os_pid, "CONT")
        signal(info.os_pid, "KILL")
        LocalCluster.stop(info.peer)

        unplanned =
          if info.status in [:killed, :frozen],
            do: state.unplanned,
            else: ["#{node} (#{info.status}, up #{now() - info.since} ms)" | state.unplanned]

        state = %{state | nodes: nodes, unplanned: unplanned, replaced: state.replaced + 1}
        {:noreply, state |> run_pending() |> boot()}
    end
  end

  def handle_info({:thawed, node}, state) do
    case state.nodes do
      %{^node => %{status: :frozen} = info} ->
        {:noreply, serve_waiting(put_in(state.nodes[node], %{info | status: :up}))}

      _ ->
        {:noreply, state}
    end
  end

  def handle_info({:checkout_timeout, ref}, state) do
    case List.keytake(state.waiting, ref, 0) do
      {{^ref, from, _timer}, waiting} ->
        GenServer.reply(from, {ref, up_nodes(state)})
        {:noreply, register(%{state | waiting: waiting}, ref)}

      nil ->
        {:noreply, state}
    end
  end

  def handle_info(_other, state), do: {:noreply, state}

  @impl GenServer
  def terminate(_reason, state) do
    # Nothing may signal an OS process after the pool: every node is
    # resumed and stopped below.
    Enum.each(state.thaws, &Process.exit(&1, :kill))
    # A node still booting is waited for, so that none outlives the pool.
    booted =
      for pid <- state.boots do
        receive do
          {:booted, ^pid, {:ok, peer, node, os_pid}} -> {node, %{peer: peer, os_pid: os_pid}}
          {:booted, ^pid, {:error, _}} -> nil
        after
          60_000 -> nil
        end
      end

    for {_node, info} <- Map.to_list(state.nodes) ++ Enum.reject(booted, &is_nil/1) do
      signal(info.os_pid, "CONT")
      LocalCluster.stop(info.peer)
      signal(info.os_pid, "KILL")
    end

    :ok
  end

  ## Helpers

  defp up_nodes(state), do: for({n, %{status: :up}} <- state.nodes, do: n) |> Enum.sort()

  defp register(state, ref),
    do: %{state | starting: Map.put(state.starting, ref, up_nodes(state))}

  defp serve_waiting(state) do
    if length(up_nodes(state)) >= state.count do
      Enum.reduce(state.waiting, %{state | waiting: []}, fn {ref, from, timer}, st ->
        Process.cancel_timer(timer)
        GenServer.reply(from, {ref, up_nodes(st)})
        register(st, ref)
      end)
    else
      state
    end
  end

  # Faults whose node no starting job uses are carried out now.
  defp run_pending(state) do
    busy = state.starting |> Map.values() |> List.flatten() |> MapSet.new()

    {ready, later} =
      Enum.split_with(state.pending, fn {_, _, node} -> not MapSet.member?(busy, node) end)

    Enum.reduce(ready, %{state | pending: later}, fn {from, fault, node}, st ->
      info = st.nodes[node]

      if info == nil do
        GenServer.reply(from, {:skipped, "#{node} went down first"})
        st
      else
        GenServer.reply(from, :ok)
        carry_out(st, fault, node, info)
      end
    end)
  end

  defp carry_out(state, :kill, node, info) do
    signal(info.os_pid, "KILL")
    put_in(state.nodes[node], %{info | status: :killed})
  end

  defp carry_out(state, {:freeze, ms}, node, info) do
    signal(info.os_pid, "STOP")
    pool = self()

    thaw =
      spawn_link(fn ->
        Process.sleep(ms)
        signal(info.os_pid, "CONT")
        send(pool, {:thawed, node})
      end)

    state = %{state | thaws: [thaw | Enum.filter(state.thaws, &Process.alive?/1)]}
    put_in(state.nodes[node], %{info | status: :frozen})
  end

  defp add(state, {:ok, peer, node, os_pid}) do
    true = :erlang.monitor_node(node, true)
    info = %{peer: peer, os_pid: os_pid, status: :up, since: now()}
    %{state | nodes: Map.put(state.nodes, node, info), started: state.started + 1}
  end

  defp add(_state, {:error, reason}), do: raise("could not start a peer node: #{reason}")

  defp boot(state) do
    pool = self()
    %{prefix: prefix, log_level: level} = state
    pid = spawn(fn -> send(pool, {:booted, self(), boot_now(prefix, level)}) end)
    %{state | boots: MapSet.put(state.boots, pid)}
  end

  defp boot_now(prefix, log_level) do
    {peer, node} = LocalCluster.start(prefix)
    :ok = :erpc.call(node, Logger, :configure, [[level: log_level]], 10_000)
    os_pid = :erpc.call(node, :os, :getpid, [], 10_000) |> List.to_string()
    {:ok, peer, node, os_pid}
  rescue
    e -> {:error, Exception.message(e)}
  catch
    kind, reason -> {:error, Exception.format(kind, reason)}
  end

  defp now, do: System.monotonic_time(:millisecond)

  defp signal(os_pid, sig) do
    _ = System.cmd("kill", ["-#{sig}", os_pid], stderr_to_stdout: true)
    :ok
  end
end
