defmodule RingTracer.Cluster do
  @moduledoc """
  The nodes a job can place children on.

  Every node that runs `:ring_tracer` joins the `:pg` group `:workers` of the
  scope `RingTracer.PG` with its `RingTracer.Children` supervisor, so
  `members/0` lists them across the cluster (`Registry` is node-local). This
  process also watches node events with `:net_kernel.monitor_nodes/1` and
  logs them; jobs themselves learn of a lost node from their monitors (a
  monitor on a process of a node that drops fires with `:noconnection`).

  `check/1` tests, before any work starts, that each node is reachable,
  runs the application, has loaded the NIF and runs the same build as this
  node (`RingTracer.Cluster.Build`). A render only connects first
  (`connect/1`): its nodes make the same checks as they start its children
  (`RingTracer.Job.Host`), so that a job starts in one round trip.
  """
  use GenServer
  require Logger

  alias RingTracer.Cluster.Build
  alias RingTracer.Error

  @scope RingTracer.PG
  @group :workers

  @doc false
  @spec child_spec(term()) :: Supervisor.child_spec()
  def child_spec(_), do: %{id: __MODULE__, start: {__MODULE__, :start_link, []}}

  @doc false
  @spec start_link() :: GenServer.on_start()
  def start_link, do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  @doc "The `:pg` scope RingTracer uses."
  @spec scope() :: atom()
  def scope, do: @scope

  @doc "Nodes that run `:ring_tracer` and are connected to this one (this node included)."
  @spec members() :: [node()]
  def members do
    @scope |> :pg.get_members(@group) |> Enum.map(&node/1) |> Enum.uniq() |> Enum.sort()
  end

  @doc """
  Connects to `nodes` and checks that each can host children: it runs the
  application, has loaded the NIF and runs this node's build. One call to
  each node, all at once. Returns `:ok` or an error naming the first node
  that cannot, and why: of reason `:build_mismatch` for a node of another
  build (both builds named), else `:node_unavailable`.

  A render makes these checks as part of starting its children (one
  round trip fewer), after `connect/1`.

      iex> RingTracer.Cluster.check([node()])
      :ok
  """
  @spec check([node()]) :: :ok | {:error, Error.t()}
  def check(nodes) do
    with :ok <- connect(nodes) do
      nodes
      |> Enum.reject(&(&1 == node()))
      |> Enum.map(&{&1, Task.async(fn -> remote_check(&1) end)})
      |> Enum.map(fn {_n, task} -> Task.await(task, :infinity) end)
      |> Enum.find(:ok, &(&1 != :ok))
      |> case do
        :ok -> :ok
        {:error, %Error{} = error} -> {:error, error}
        {:error, message} -> {:error, Error.new(:node_unavailable, message)}
      end
    end
  end

  @doc """
  Connects to `nodes` (no call to them beyond distribution's own
  handshake). Returns `:ok` or an error of reason `:node_unavailable`
  naming the first node that cannot be reached, and why.

      iex> RingTracer.Cluster.connect([node()])
      :ok
  """
  @spec connect([node()]) :: :ok | {:error, Error.t()}
  def connect(nodes) do
    Enum.reduce_while(nodes, :ok, fn n, :ok ->
      case connect_node(n) do
        :ok -> {:cont, :ok}
        {:error, message} -> {:halt, {:error, Error.new(:node_unavailable, message)}}
      end
    end)
  end

  defp connect_node(n) when n == node(), do: :ok

  defp connect_node(n) do
    cond do
      not Node.alive?() ->
        {:error,
         "cannot use node #{n}: this node is not distributed; start it with --sname NAME " <>
           "(the cookie comes from --cookie-file, default ~/.erlang.cookie)"}

      not Node.connect(n) ->
        {:error, "cannot connect to node #{n}: #{RingTracer.Cluster.TLS.diagnose(n)}"}

      true ->
        :ok
    end
  end

  @doc """
  Why a call to `node` failed, in words, from what `:erpc` raised (`reason`)
  or the exit of a call to a process there; `ms` is the call's timeout.

      iex> RingTracer.Cluster.call_failure(:w1@host, {:erpc, :timeout}, 5_000)
      "node w1@host did not answer within 5000 ms (frozen or overloaded)"
      iex> RingTracer.Cluster.call_failure(:w1@host, {:erpc, :noconnection}, 5_000)
      "lost the connection to node w1@host (it went down, or stopped answering for longer than the liveness timeout)"
  """
  @spec call_failure(node(), term(), timeout()) :: String.t()
  def call_failure(node, reason, ms) do
    cond do
      reason == {:erpc, :timeout} ->
        "node #{node} did not answer within #{ms} ms (frozen or overloaded)"

      lost?(reason) ->
        "lost the connection to node #{node} (it went down, or stopped answering for longer " <>
          "than the liveness timeout)"

      true ->
        "node #{node}: #{inspect(reason)}"
    end
  end

  # A dropped connection, as :erpc raises it or as the exit of a call
  # (GenServer's wraps the reason with the call).
  defp lost?(:noconnection), do: true
  defp lost?({:erpc, :noconnection}), do: true
  defp lost?({:nodedown, _}), do: true
  defp lost?({reason, {GenServer, :call, _}}), do: lost?(reason)
  defp lost?(_), do: false

  @check_ms 5_000

  # One call: the node's own test (`RingTracer.Job.Host.check/1`, what a
  # job's start asks too).
  defp remote_check(n) do
    case :erpc.call(n, RingTracer.Job.Host, :check, [Build.identity()], @check_ms) do
      :ok -> :ok
      {:build, theirs} -> Build.compare(n, theirs)
      {:error, {_reason, message}} -> {:error, message}
    end
  catch
    :error, {:erpc, _} = reason ->
      {:error, call_failure(n, reason, @check_ms)}

    :error, {:exception, reason, _} ->
      {:error, "node #{n} lacks RingTracer's code or NIF: #{inspect(reason)}"}

    kind, reason ->
      {:error, "node #{n}: #{inspect({kind, reason})}"}
  end

  @impl GenServer
  def init([]) do
    # The NIF's part of this node's build, now that it is loaded; the rest
    # once this process has started, so that no check waits for it.
    :ok = Build.init()

    :ok = :pg.join(@scope, @group, Process.whereis(RingTracer.Children))
    :ok = :net_kernel.monitor_nodes(true)
    {:ok, %{}, {:continue, :build}}
  end

  @impl GenServer
  def handle_continue(:build, state) do
    _ = Build.identity()
    {:noreply, state}
  end

  @impl GenServer
  def handle_info({:nodeup, n}, state) do
    Logger.debug("RingTracer: node #{n} up")
    {:noreply, state}
  end

  def handle_info({:nodedown, n}, state) do
    # Nodes connect to each other through the workers they share: another
    # render's VM going is no news for the renders of this one.
    if hosts_our_children?(n),
      do: Logger.info("RingTracer: node #{n} down; jobs with children there re-link their rings"),
      else: Logger.debug("RingTracer: node #{n} down")

    {:noreply, state}
  end

  @doc false
  # Whether a job with children on this node also has one on `n` (its ring,
  # published in this node's `RingTracer.Job.Directory`).
  @spec hosts_our_children?(node()) :: boolean()
  def hosts_our_children?(n) do
    RingTracer.Job.Directory.any_on?(n)
  rescue
    # no table: the application is not running here
    ArgumentError -> false
  end
end
