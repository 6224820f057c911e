defmodule RingTracer.Job.Directory do
  @moduledoc """
  Where a job's children find each other: one table per node, holding for
  each running job the pid of every child by its index.

  A child may send to any sibling (an aimed help offer, a steal, a
  hand-over to an offer's origin), so it needs every sibling's pid. Giving
  each child its own copy of the ring would cost O(N) per child and O(N²)
  per job (16,384 children would hold 2 GiB of pids); instead the parent
  publishes the ring once on each node its children run on, before any
  child starts work, and a child looks a sibling up in its node's table
  when it needs one (`sibling/2`, an ETS read, no message).

  This process owns the table and monitors each job's parent: when the
  parent ends, normally or not, its rows go.
  """
  use GenServer

  @table RingTracer.Names.directory_table()

  @doc false
  @spec start_link(term()) :: GenServer.on_start()
  def start_link(_), do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  @doc """
  Publishes job `id`'s children (`pids`, by index) on `node` for as long as
  `parent` lives. Waits at most `timeout` ms for the node to answer.
  """
  @spec publish(node(), reference(), pid(), tuple(), timeout()) :: :ok | {:error, term()}
  def publish(node, id, parent, pids, timeout) when is_tuple(pids) do
    GenServer.call({__MODULE__, node}, {:publish, id, parent, pids}, timeout)
  catch
    :exit, reason -> {:error, reason}
  end

  @doc "The pid of child `index` of job `id`, from this node's table."
  @spec sibling(reference(), non_neg_integer()) :: pid()
  def sibling(id, index), do: :ets.lookup_element(@table, {id, index}, 2)

  @doc "Whether a job in this node's table has a child on `node`."
  @spec any_on?(node()) :: boolean()
  def any_on?(node) do
    spec = [{{:_, :"$1"}, [{:==, {:node, :"$1"}, node}], [true]}]
    match?({[_ | _], _}, :ets.select(@table, spec, 1))
  end

  @doc "How many jobs this node's table holds (for tests and diagnostics)."
  @spec jobs() :: non_neg_integer()
  def jobs, do: GenServer.call(__MODULE__, :jobs)

  @impl GenServer
  def init([]) do
    :ets.new(@table, [:named_table, :set, :protected, read_concurrency: true])
    {:ok, %{ids: %{}, refs: %{}}}
  end

  @impl GenServer
  def handle_call({:publish, id, parent, pids}, _from, state) do
    rows = for i <- 0..(tuple_size(pids) - 1)//1, do: {{id, i}, elem(pids, i)}
    true = :ets.insert(@table, rows)

    state =
      if is_map_key(state.ids, id) do
        state
      else
        ref = Process.monitor(parent)
        %{ids: Map.put(state.ids, id, ref), refs: Map.put(state.refs, ref, id)}
      end

    {:reply, :ok, state}
  end

  def handle_call(:jobs, _from, state), do: {:reply, map_size(state.ids), state}

  @impl GenServer
  def handle_info({:DOWN, ref, :process, _parent, _reason}, state) do
    {id, refs} = Map.pop(state.refs, ref)
    if id != nil, do: :ets.match_delete(@table, {{id, :_}, :_})
    {:noreply, %{ids: Map.delete(state.ids, id), refs: refs}}
  end
end
