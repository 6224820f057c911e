defmodule RingTracer.SceneCache do
  @moduledoc """
  One per node: parsed scenes by content hash, so that every child of a job
  on this node (and later jobs of the same scene) share one parsed scene and
  BVH.

  Reads go straight to a protected ETS table; a miss asks the cache process,
  which parses (one parse at a time, so two children asking for the same new
  scene parse it once). At most `max_entries` scenes are kept (default 4,
  application env `:scene_cache_entries`); the least recently used is dropped
  first. A dropped scene's memory is freed when the last process holding it
  lets go.
  """
  use GenServer

  alias RingTracer.Scene
  alias RingTracer.Scene.Source

  @table __MODULE__

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: __MODULE__)

  @doc "The parsed scene for `source` on this node, parsing it on a miss."
  @spec fetch(Source.t()) :: {:ok, Scene.t()} | {:error, RingTracer.Error.t()}
  def fetch(%Source{hash: hash} = source) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene, _used}] ->
        GenServer.cast(__MODULE__, {:touch, hash})
        {:ok, scene}

      [] ->
        GenServer.call(__MODULE__, {:fetch, source}, :infinity)
    end
  end

  @doc """
  Parses `source` on this node unless it is cached already: what a job's
  parent calls once per node (through `:erpc`) before starting children there.
  """
  @spec preload(Source.t()) :: :ok | {:error, String.t()}
  def preload(source) do
    case fetch(source) do
      {:ok, _} -> :ok
      {:error, error} -> {:error, error.message}
    end
  end

  @doc "Puts an already parsed scene in the cache (the caller's node parses to validate)."
  @spec put(Scene.t()) :: :ok
  def put(%Scene{} = scene), do: GenServer.call(__MODULE__, {:put, scene})

  @doc "Number of cached scenes."
  @spec size() :: non_neg_integer()
  def size, do: :ets.info(@table, :size)

  @doc "Drops every cached scene."
  @spec clear() :: :ok
  def clear, do: GenServer.call(__MODULE__, :clear)

  @impl GenServer
  def init(opts) do
    max =
      Keyword.get(opts, :max_entries, Application.get_env(:ring_tracer, :scene_cache_entries, 4))

    :ets.new(@table, [:named_table, :protected, :set, read_concurrency: true])
    {:ok, %{max: max, clock: 0}}
  end

  @impl GenServer
  def handle_call({:fetch, %Source{hash: hash} = source}, _from, state) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene, _}] ->
        {:reply, {:ok, scene}, touch(state, hash)}

      [] when source.bytes == nil ->
        message =
          "scene #{source.name} is not cached on #{node()} and was shipped without its bytes"

        {:reply, {:error, RingTracer.Error.new(:invalid_scene, message)}, state}

      [] ->
        case Scene.from_source(source) do
          {:ok, scene} -> {:reply, {:ok, scene}, insert(state, scene)}
          error -> {:reply, error, state}
        end
    end
  end

  def handle_call({:put, scene}, _from, state), do: {:reply, :ok, insert(state, scene)}

  def handle_call(:clear, _from, state) do
    :ets.delete_all_objects(@table)
    {:reply, :ok, state}
  end

  @impl GenServer
  def handle_cast({:touch, hash}, state), do: {:noreply, touch(state, hash)}

  defp touch(state, hash) do
    clock = state.clock + 1
    :ets.update_element(@table, hash, {3, clock})
    %{state | clock: clock}
  end

  defp insert(state, %Scene{source: %Source{hash: hash}} = scene) do
    clock = state.clock + 1
    :ets.insert(@table, {hash, scene, clock})
    evict(state.max)
    %{state | clock: clock}
  end

  defp evict(max) do
    if :ets.info(@table, :size) > max do
      [{hash, _} | _] =
        @table
        |> :ets.select([{{:"$1", :_, :"$2"}, [], [{{:"$1", :"$2"}}]}])
        |> Enum.sort_by(&elem(&1, 1))

      :ets.delete(@table, hash)
      evict(max)
    end
  end
end
