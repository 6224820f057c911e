defmodule RingTracer.Job.Directory do
  @moduledoc false
  # Where a job's children find each other: one table per node, holding for
  # each running job the pid of every child by its index.
  #
  # A child may send to any sibling (an aimed help offer, a steal, a
  # hand-over to an offer's origin), so it needs every sibling's pid. Giving
  # each child its own copy of the ring would cost O(N) per child and O(N²)
  # per job (16,384 children would hold 2 GiB of pids); instead the parent
  # publishes the ring once on each node its children run on, a message sent
  # just before it tells the children of their ring, and a child waits until
  # its node's table holds that ring (`await/3`, at once in the usual case)
  # and looks a sibling up there when it needs one (`sibling/2`, an ETS
  # read, no message).
  #
  # This process owns the table and monitors each job's parent: when the
  # parent ends, normally or not, its rows go.
  use GenServer

  @table RingTracer.Names.directory_table()

  @doc false
  @spec start_link(term()) :: GenServer.on_start()
  def start_link(_), do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  @doc """
  Publishes job `id`'s children (`pids`, by index) on `node` for as long as
  `parent` lives: a message, with no answer to wait for. A child waits
  for the ring it is told of with `await/3` before it looks a sibling up.
  """
  @spec publish(node(), reference(), pid(), tuple()) :: :ok
  def publish(node, id, parent, pids) when is_tuple(pids),
    do: GenServer.cast({__MODULE__, node}, {:publish, id, parent, pids})

  @doc """
  Waits, at most `timeout` ms, until this node's table holds job `id`'s
  ring of at least `size` children.
  """
  @spec await(reference(), pos_integer(), timeout()) :: :ok | {:error, :timeout}
  def await(id, size, timeout) do
    if :ets.member(@table, {id, size - 1}),
      do: :ok,
      else: GenServer.call(__MODULE__, {:await, id, size, timeout}, timeout)
  catch
    :exit, {:timeout, _} -> {:error, :timeout}
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
    {:ok, %{ids: %{}, refs: %{}, waiting: %{}}}
  end

  @impl GenServer
  def handle_cast({:publish, id, parent, pids}, state) do
    rows = for i <- 0..(tuple_size(pids) - 1)//1, do: {{id, i}, elem(pids, i)}
    true = :ets.insert(@table, rows)

    state =
      if is_map_key(state.ids, id) do
        state
      else
        ref = Process.monitor(parent)
        %{state | ids: Map.put(state.ids, id, ref), refs: Map.put(state.refs, ref, id)}
      end

    {ready, still} =
      state.waiting |> Map.get(id, []) |> Enum.split_with(&(elem(&1, 1) <= tuple_size(pids)))

    Enum.each(ready, fn {from, _, _} -> GenServer.reply(from, :ok) end)
    {:noreply, %{state | waiting: Map.put(state.waiting, id, still)} |> prune()}
  end

  @impl GenServer
  def handle_call({:await, id, size, timeout}, from, state) do
    if :ets.member(@table, {id, size - 1}) do
      {:reply, :ok, state}
    else
      until = if timeout == :infinity, do: :infinity, else: now() + timeout
      waiter = {from, size, until}

      {:noreply,
       prune(%{state | waiting: Map.update(state.waiting, id, [waiter], &[waiter | &1])})}
    end
  end

  def handle_call(:jobs, _from, state), do: {:reply, map_size(state.ids), state}

  # Waiters whose call has timed out (their job's ring never came here) go.
  defp prune(state) do
    t = now()

    waiting =
      for {id, waiters} <- state.waiting,
          kept = Enum.filter(waiters, fn {_, _, until} -> until == :infinity or until > t end),
          kept != [],
          into: %{},
          do: {id, kept}

    %{state | waiting: waiting}
  end

  defp now, do: System.monotonic_time(:millisecond)

  @impl GenServer
  def handle_info({:DOWN, ref, :process, _parent, _reason}, state) do
    {id, refs} = Map.pop(state.refs, ref)
    if id != nil, do: :ets.match_delete(@table, {{id, :_}, :_})

    {:noreply,
     %{state | ids: Map.delete(state.ids, id), refs: refs, waiting: Map.delete(state.waiting, id)}}
  end
end
