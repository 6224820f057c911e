defmodule RingTracer.SceneCache do
  @moduledoc """
  One per node: parsed scenes by content hash, so that every child of a job
  on this node (and later jobs of the same scene) share one parsed scene and
  BVH.

  Reads go straight to a protected ETS table; a miss asks the cache process,
  which parses (one parse at a time, so two children asking for the same new
  scene parse it once).

  **Pins.** A job's parent pins its scene on every node it uses before it
  starts children there (`pin/2`, with the scene's bytes), and the pin lasts
  until the parent ends (the cache monitors it) or `unpin/2`. A pinned scene
  is never evicted, so any number of concurrent jobs, with any number of
  distinct scenes, find their scene when their children fetch it.

  **Eviction** is bounded by bytes: when the scenes held exceed
  `max_bytes` (application env `:scene_cache_bytes`, default 256 MiB of
  scene source, references included), the least recently used *unpinned*
  scenes are dropped until they fit, or until only pinned ones are left. A
  dropped scene's memory is freed when the last process holding it lets go.
  """
  use GenServer

  alias RingTracer.Scene
  alias RingTracer.Scene.Source

  @table __MODULE__
  @default_bytes 256 * 1024 * 1024

  @typep entry :: %{size: non_neg_integer(), used: non_neg_integer(), pins: MapSet.t()}
  @typep state :: %{
           max_bytes: non_neg_integer(),
           clock: non_neg_integer(),
           entries: %{binary() => entry()},
           monitors: %{reference() => {binary(), pid()}}
         }

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: __MODULE__)

  @doc "The parsed scene for `source` on this node, parsing it on a miss."
  @spec fetch(Source.t()) :: {:ok, Scene.t()} | {:error, RingTracer.Error.t()}
  def fetch(%Source{hash: hash} = source) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene}] ->
        GenServer.cast(__MODULE__, {:touch, hash})
        {:ok, scene}

      [] ->
        GenServer.call(__MODULE__, {:fetch, source}, :infinity)
    end
  end

  @doc """
  Parses `source` on this node unless it is cached, and pins it for `owner`
  (a job's parent) until `owner` ends. What a parent calls once per node
  (through `:erpc` for other nodes) before starting children there.
  """
  @spec pin(Source.t(), pid()) :: :ok | {:error, String.t()}
  def pin(%Source{} = source, owner) when is_pid(owner) do
    case GenServer.call(__MODULE__, {:pin, source, owner}, :infinity) do
      :ok -> :ok
      {:error, error} -> {:error, error.message}
    end
  end

  @doc "Releases `owner`'s pin on the scene `hash`."
  @spec unpin(binary(), pid()) :: :ok
  def unpin(hash, owner), do: GenServer.call(__MODULE__, {:unpin, hash, owner})

  @doc "Puts an already parsed scene in the cache (the caller's node parses to validate)."
  @spec put(Scene.t()) :: :ok
  def put(%Scene{} = scene), do: GenServer.call(__MODULE__, {:put, scene})

  @doc "Sets the byte budget (see the module doc) and evicts what no longer fits."
  @spec set_max_bytes(non_neg_integer()) :: :ok
  def set_max_bytes(bytes) when is_integer(bytes) and bytes >= 0,
    do: GenServer.call(__MODULE__, {:max_bytes, bytes})

  @doc "The hashes of the scenes held, and for each its size and how many pins it has."
  @spec info() :: %{binary() => %{size: non_neg_integer(), pins: non_neg_integer()}}
  def info do
    GenServer.call(__MODULE__, :info)
  end

  @impl GenServer
  def init(opts) do
    max =
      Keyword.get_lazy(opts, :max_bytes, fn ->
        Application.get_env(:ring_tracer, :scene_cache_bytes, @default_bytes)
      end)

    :ets.new(@table, [:named_table, :protected, :set, read_concurrency: true])
    {:ok, %{max_bytes: max, clock: 0, entries: %{}, monitors: %{}}}
  end

  @impl GenServer
  def handle_call({:fetch, %Source{} = source}, _from, state) do
    case load(state, source) do
      {:ok, scene, state} -> {:reply, {:ok, scene}, evict(state)}
      {:error, error, state} -> {:reply, {:error, error}, state}
    end
  end

  def handle_call({:pin, %Source{hash: hash} = source, owner}, _from, state) do
    case load(state, source) do
      {:ok, _scene, state} ->
        ref = Process.monitor(owner)

        state =
          %{state | monitors: Map.put(state.monitors, ref, {hash, owner})}
          |> update_entry(hash, &%{&1 | pins: MapSet.put(&1.pins, ref)})

        {:reply, :ok, evict(state)}

      {:error, error, state} ->
        {:reply, {:error, error}, state}
    end
  end

  def handle_call({:unpin, hash, owner}, _from, state) do
    refs = for {ref, {^hash, ^owner}} <- state.monitors, do: ref
    Enum.each(refs, &Process.demonitor(&1, [:flush]))
    {:reply, :ok, state |> drop_pins(refs) |> evict()}
  end

  def handle_call({:put, scene}, _from, state), do: {:reply, :ok, evict(insert(state, scene))}

  def handle_call({:max_bytes, bytes}, _from, state),
    do: {:reply, :ok, evict(%{state | max_bytes: bytes})}

  def handle_call(:info, _from, state) do
    {:reply,
     Map.new(state.entries, fn {h, e} -> {h, %{size: e.size, pins: MapSet.size(e.pins)}} end),
     state}
  end

  @impl GenServer
  def handle_cast({:touch, hash}, state), do: {:noreply, touch(state, hash)}

  @impl GenServer
  def handle_info({:DOWN, ref, :process, _, _}, state),
    do: {:noreply, state |> drop_pins([ref]) |> evict()}

  @spec load(state(), Source.t()) ::
          {:ok, Scene.t(), state()} | {:error, RingTracer.Error.t(), state()}
  defp load(state, %Source{hash: hash} = source) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene}] ->
        {:ok, scene, touch(state, hash)}

      [] when source.bytes == nil ->
        message =
          "scene #{source.name} is not cached on #{node()} and was shipped without its bytes"

        {:error, RingTracer.Error.new(:invalid_scene, message), state}

      [] ->
        case Scene.from_source(source) do
          {:ok, scene} -> {:ok, scene, insert(state, scene)}
          {:error, error} -> {:error, error, state}
        end
    end
  end

  defp drop_pins(state, refs) do
    Enum.reduce(refs, state, fn ref, st ->
      case Map.pop(st.monitors, ref) do
        {nil, _} ->
          st

        {{hash, _owner}, monitors} ->
          update_entry(
            %{st | monitors: monitors},
            hash,
            &%{&1 | pins: MapSet.delete(&1.pins, ref)}
          )
      end
    end)
  end

  defp update_entry(state, hash, fun) do
    case state.entries do
      %{^hash => entry} -> %{state | entries: Map.put(state.entries, hash, fun.(entry))}
      _ -> state
    end
  end

  defp touch(state, hash) do
    clock = state.clock + 1
    %{update_entry(state, hash, &%{&1 | used: clock}) | clock: clock}
  end

  defp insert(state, %Scene{source: %Source{hash: hash} = source} = scene) do
    clock = state.clock + 1
    :ets.insert(@table, {hash, scene})
    pins = get_in(state.entries, [hash, :pins]) || MapSet.new()
    entry = %{size: Source.size(source), used: clock, pins: pins}
    %{state | clock: clock, entries: Map.put(state.entries, hash, entry)}
  end

  # Least recently used unpinned scenes go first, while the total exceeds
  # the budget.
  defp evict(state) do
    total = state.entries |> Map.values() |> Enum.map(& &1.size) |> Enum.sum()

    if total > state.max_bytes do
      state.entries
      |> Enum.filter(fn {_, e} -> MapSet.size(e.pins) == 0 end)
      |> Enum.min_by(fn {_, e} -> e.used end, fn -> nil end)
      |> case do
        nil ->
          state

        {hash, _} ->
          :ets.delete(@table, hash)
          evict(%{state | entries: Map.delete(state.entries, hash)})
      end
    else
      state
    end
  end
end
