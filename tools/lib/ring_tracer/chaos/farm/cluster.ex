defmodule RingTracer.Chaos.Farm.Cluster do
  @moduledoc false
  # The farm soak's nodes, each a real OS process on this machine
  # (`RingTracer.LocalCluster`): a head (`RingTracer.Farm.start_head/1`),
  # which `kill_head/1` kills with SIGKILL and starts again under the same
  # node name and folder (so Mnesia recovers its queue), and workers
  # (`RingTracer.Farm.join/2`, all tagged `RingTracer.Chaos.Farm.Schedule.tag/0`),
  # which may be killed (SIGKILL), frozen (SIGSTOP, then SIGCONT by `thaw/2`)
  # and added. Workers join the restarted head by themselves.

  alias RingTracer.Chaos.Farm.Schedule
  alias RingTracer.Cluster.Distribution
  alias RingTracer.Farm
  alias RingTracer.LocalCluster

  @down_ms 15_000

  defmodule Worker do
    @moduledoc false
    # A worker node: its `:peer` process, OS pid, and when it thaws if frozen.
    @enforce_keys [:peer, :os_pid]
    defstruct [:peer, :os_pid, thaw_at: nil]

    @type t :: %__MODULE__{peer: pid(), os_pid: String.t(), thaw_at: integer() | nil}
  end

  @enforce_keys [:name, :node, :dir, :peer, :os_pid, :speed, :log_level]
  defstruct [:name, :node, :dir, :peer, :os_pid, :speed, :log_level, workers: %{}]

  @typedoc "`name`: the head's name as given to `:peer` (`node` without its host)."
  @type t :: %__MODULE__{
          name: atom(),
          node: node(),
          dir: Path.t(),
          peer: pid(),
          os_pid: String.t(),
          speed: number(),
          log_level: Logger.level(),
          workers: %{node() => Worker.t()}
        }

  @doc """
  Starts the head (its folder `dir`) and `count` workers, and waits until
  every worker has joined. Options: `:speed` (each worker emulates a
  machine this many times slower, default 1) and `:log_level` of the peers
  (default `:error`: the soak makes nodes drop on purpose).
  """
  @spec start(Path.t(), non_neg_integer(), keyword()) :: t()
  def start(dir, count, opts \\ []) do
    LocalCluster.ensure_distributed()
    name = String.to_atom(Distribution.unique_name("farmhead"))
    level = Keyword.get(opts, :log_level, :error)
    {peer, node, os_pid} = start_head(name, dir, level)

    cluster = %__MODULE__{
      name: name,
      node: node,
      dir: dir,
      peer: peer,
      os_pid: os_pid,
      speed: Keyword.get(opts, :speed, 1),
      log_level: level
    }

    cluster = Enum.reduce(1..count//1, cluster, fn _, c -> add_worker(c) end)
    :ok = await_workers(cluster, map_size(cluster.workers))
    cluster
  end

  @doc "The head's node name."
  @spec head(t()) :: node()
  def head(%__MODULE__{node: node}), do: node

  @doc "Kills the head with SIGKILL, starts it again (same name and folder) and waits for it."
  @spec kill_head(t()) :: t()
  def kill_head(%__MODULE__{node: node} = c) do
    :ok = kill9(c.peer, c.os_pid)
    {peer, ^node, os_pid} = start_head(c.name, c.dir, c.log_level)
    %{c | peer: peer, os_pid: os_pid}
  end

  @doc "Workers up (not frozen), by name."
  @spec up(t()) :: [node()]
  def up(%__MODULE__{workers: workers}),
    do: for({node, %Worker{thaw_at: nil}} <- workers, do: node) |> Enum.sort()

  @doc "Kills a worker with SIGKILL and waits until it is gone."
  @spec kill_worker(t(), node()) :: t()
  def kill_worker(%__MODULE__{} = c, node) do
    {worker, workers} = Map.pop!(c.workers, node)
    :ok = kill9(worker.peer, worker.os_pid)
    %{c | workers: workers}
  end

  @doc "Stops a worker's OS process (SIGSTOP) for `ms` milliseconds (see `thaw/2`)."
  @spec freeze_worker(t(), node(), pos_integer()) :: t()
  def freeze_worker(%__MODULE__{} = c, node, ms) do
    signal(c.workers[node].os_pid, "STOP")
    put_in(c.workers[node].thaw_at, now() + ms)
  end

  @doc """
  Resumes (SIGCONT) the frozen workers whose time has come, and forgets
  workers whose node went down by itself (e.g. a `:peer` node that lost its
  connection while frozen): returns them with the cluster.
  """
  @spec thaw(t(), :due | :all) :: {t(), [node()]}
  def thaw(%__MODULE__{} = c, which) do
    at = now()

    workers =
      Map.new(c.workers, fn
        {node, %Worker{thaw_at: t} = w} when is_integer(t) and (which == :all or t <= at) ->
          signal(w.os_pid, "CONT")
          {node, %{w | thaw_at: nil}}

        other ->
          other
      end)

    {gone, alive} = Enum.split_with(workers, fn {_, w} -> not Process.alive?(w.peer) end)
    {%{c | workers: Map.new(alive)}, Enum.map(gone, &elem(&1, 0))}
  end

  @doc "Starts one more worker and joins it to the head."
  @spec add_worker(t()) :: t()
  def add_worker(%__MODULE__{} = c) do
    {peer, node} = LocalCluster.start("farmw")
    :ok = :erpc.call(node, Logger, :configure, [[level: c.log_level]], 10_000)
    os_pid = :erpc.call(node, :os, :getpid, [], 10_000) |> List.to_string()

    {:ok, _} =
      :erpc.call(
        node,
        Farm,
        :join,
        [c.node, [slots: 1, speed: c.speed, tags: [Schedule.tag()]]],
        10_000
      )

    put_in(c.workers[node], %Worker{peer: peer, os_pid: os_pid})
  end

  @doc "Waits (up to 30 s) until the head lists at least `count` workers."
  @spec await_workers(t(), non_neg_integer()) :: :ok | {:error, String.t()}
  def await_workers(%__MODULE__{} = c, count), do: await_workers(c, count, now() + 30_000)

  defp await_workers(c, count, deadline) do
    case Farm.workers(c.node, timeout: 2_000) do
      {:ok, workers} when length(workers) >= count ->
        :ok

      _ ->
        if now() > deadline do
          {:error, "the head did not list #{count} workers within 30 s"}
        else
          Process.sleep(100)
          await_workers(c, count, deadline)
        end
    end
  end

  @doc "Resumes and stops every node."
  @spec stop(t()) :: :ok
  def stop(%__MODULE__{} = c) do
    for {_, w} <- c.workers do
      signal(w.os_pid, "CONT")
      LocalCluster.stop(w.peer)
      signal(w.os_pid, "KILL")
    end

    LocalCluster.stop(c.peer)
    signal(c.os_pid, "KILL")
    :ok
  end

  defp start_head(name, dir, level) do
    {peer, node} = LocalCluster.start("farmhead", name: name)
    :ok = :erpc.call(node, Logger, :configure, [[level: level]], 10_000)
    {:ok, _} = :erpc.call(node, Farm, :start_head, [[dir: dir]], 60_000)
    {peer, node, :erpc.call(node, :os, :getpid, [], 10_000) |> List.to_string()}
  end

  defp kill9(peer, os_pid) do
    ref = Process.monitor(peer)
    signal(os_pid, "CONT")
    signal(os_pid, "KILL")

    receive do
      {:DOWN, ^ref, :process, _, _} -> :ok
    after
      @down_ms -> raise "node of OS pid #{os_pid} did not go down after SIGKILL"
    end
  end

  defp signal(os_pid, sig) do
    _ = System.cmd("kill", ["-#{sig}", os_pid], stderr_to_stdout: true)
    :ok
  end

  defp now, do: System.monotonic_time(:millisecond)
end
