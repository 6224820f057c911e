defmodule RingTracer.Telemetry do
  @moduledoc """
  Job events, named and shaped as `:telemetry` would have them (the
  telemetry package cannot be installed here), through the same small API:
  attach a function to an event, detach it by its id.

  Events, emitted on the node of the job's parent, in the parent:

    * `[:ring_tracer, :job, :start]` — measurements `%{system_time: native}`,
      metadata `%{job: id, children: n, atoms: total, strategy: module,
      description: map}` (the description holds the job's layout, strategy,
      nodes and speeds, and its start time: what a live preview draws)
    * `[:ring_tracer, :atom, :stop]` — an atom's pixels reached the parent:
      measurements `%{rays: n, trace_us: us}` (rays of every kind), metadata
      `%{job: id, atom: a, child: index, node: the child's node, done:
      atoms_done, total: atoms}`
    * `[:ring_tracer, :frame, :start]` — a job of several frames released a
      frame: measurements `%{at_us: job_us}`, metadata `%{job: id, frame:
      number}` (the scene's frame number, from 1)
    * `[:ring_tracer, :frame, :stop]` — a sequence's frame is complete:
      measurements `%{at_us: job_us, elapsed_us: us}`, metadata `%{job: id,
      frame: %RingTracer.Frame{}}` (its pixels included)
    * `[:ring_tracer, :job, :grown]` — children joined the running job
      (`RingTracer.grow/4`): measurements `%{children: count, system_time:
      native}`, metadata `%{job: id, node: node, joined: [index], size:
      children_now}`; `[:ring_tracer, :job, :shrunk]` — a node's children
      leave it (`RingTracer.shrink/3`): metadata `%{job: id, node: node,
      leaving: [index]}`
    * `[:ring_tracer, :job, :stop]` — measurements `%{duration: native}`,
      metadata `%{job: id, outcome: :ok | :error}`

  A handler runs in the emitting process, so it must be quick (send a
  message, bump a counter). One that raises is detached, as `:telemetry`
  does, and the job goes on.

      iex> me = self()
      iex> :ok = RingTracer.Telemetry.attach("doc", [:ring_tracer, :atom, :stop], fn _e, m, _md, _c -> send(me, m.rays) end, nil)
      iex> {:ok, _} = RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 8, children: 1, atoms: 1)
      iex> RingTracer.Telemetry.detach("doc")
      :ok
      iex> receive do rays -> rays > 0 end
      true
  """
  use GenServer

  require Logger

  @table __MODULE__

  @type event :: [atom()]
  @type handler :: (event(), map(), map(), term() -> any())

  @doc false
  @spec start_link(term()) :: GenServer.on_start()
  def start_link(_), do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  @doc "Calls `fun.(event, measurements, metadata, config)` on every `event`, until detached."
  @spec attach(term(), event(), handler(), term()) :: :ok | {:error, :already_exists}
  def attach(id, event, fun, config) when is_list(event) and is_function(fun, 4),
    do: GenServer.call(__MODULE__, {:attach, id, event, fun, config})

  @doc "Detaches the handler `id`."
  @spec detach(term()) :: :ok | {:error, :not_found}
  def detach(id), do: GenServer.call(__MODULE__, {:detach, id})

  @doc "Emits `event` to its handlers on this node."
  @spec execute(event(), map(), map()) :: :ok
  def execute(event, measurements, metadata) do
    handlers =
      try do
        :ets.lookup(@table, event)
      rescue
        ArgumentError -> []
      end

    for {_event, id, fun, config} <- handlers do
      try do
        fun.(event, measurements, metadata, config)
      catch
        kind, reason ->
          Logger.warning(
            "RingTracer.Telemetry: handler #{inspect(id)} failed (#{inspect({kind, reason})}); detached"
          )

          detach(id)
      end
    end

    :ok
  end

  @doc false
  # A child's protocol event (`RingTracer.Job.Child.event/3`).
  @spec child_event(reference(), atom(), non_neg_integer(), term(), integer()) :: :ok
  def child_event(job, kind, from, to, at),
    do:
      execute([:ring_tracer, :child, :event], %{at_us: at}, %{
        job: job,
        kind: kind,
        from: from,
        to: to
      })

  @impl GenServer
  def init([]) do
    :ets.new(@table, [:named_table, :bag, :protected, read_concurrency: true])
    {:ok, nil}
  end

  @impl GenServer
  def handle_call({:attach, id, event, fun, config}, _from, state) do
    if :ets.match_object(@table, {:_, id, :_, :_}) == [] do
      :ets.insert(@table, {event, id, fun, config})
      {:reply, :ok, state}
    else
      {:reply, {:error, :already_exists}, state}
    end
  end

  def handle_call({:detach, id}, _from, state) do
    case :ets.match_object(@table, {:_, id, :_, :_}) do
      [] ->
        {:reply, {:error, :not_found}, state}

      rows ->
        Enum.each(rows, &:ets.delete_object(@table, &1))
        {:reply, :ok, state}
    end
  end
end
