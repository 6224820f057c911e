defmodule RingTracer.SceneCache do
  @moduledoc false
  # One per node: parsed scenes by content hash, so that every child of a job
  # on this node (and later jobs of the same scene) share one parsed scene and
  # BVH.
  #
  # Reads go straight to a protected ETS table; a miss asks the cache process,
  # which parses (one parse at a time, so two children asking for the same new
  # scene parse it once).
  #
  # **Pins.** A job's parent pins its scene on every node it uses before it
  # starts children there (`pin/2`, with the scene's bytes), and the pin lasts
  # until the parent ends (the cache monitors it) or `unpin/2`. A pinned scene
  # is never evicted, so any number of concurrent jobs, with any number of
  # distinct scenes, find their scene when their children fetch it.
  #
  # **Eviction** is bounded by bytes: when the scenes held exceed
  # `max_bytes` (application env `:scene_cache_bytes`, default 256 MiB of
  # scene source, references included), the least recently used *unpinned*
  # scenes are dropped until they fit, or until only pinned ones are left. A
  # dropped scene's memory is freed when the last process holding it lets go.
  #
  # **Frames.** The scene of a frame of an animation (`fetch_frame/2`), keyed
  # by the scene's hash and the frame, is cached the same way: read from the
  # table, built on a miss by the cache process (one build at a time, so the
  # children of a job on this node build each frame once). Frame 0 is the
  # scene itself. At most `max_frames` frames of each scene are held
  # (application env `:scene_cache_frames`, default 8), the least recently
  # fetched going first, and a scene's frames go with it when it is evicted.
  # A dropped frame is freed when the last process holding it (say, a
  # grandchild tracing it) lets go.
  use GenServer

  alias RingTracer.{Error, Native, Scene}
  alias RingTracer.Scene.Source

  @table __MODULE__
  @default_bytes 256 * 1024 * 1024
  @default_frames 8

  @typep entry :: %{size: non_neg_integer(), used: non_neg_integer(), pins: MapSet.t()}
  @typep state :: %{
           max_bytes: non_neg_integer(),
           max_frames: non_neg_integer(),
           clock: non_neg_integer(),
           entries: %{binary() => entry()},
           frames: %{binary() => %{non_neg_integer() => non_neg_integer()}},
           monitors: %{reference() => {binary(), pid()}}
         }

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: __MODULE__)

  @doc "The parsed scene for `source` on this node, parsing it on a miss."
  @spec fetch(Source.t()) :: {:ok, Scene.t()} | {:error, Error.t()}
  def fetch(%Source{hash: hash} = source) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene}] ->
        GenServer.cast(__MODULE__, {:touch, hash})
        {:ok, scene}

      [] ->
        GenServer.call(__MODULE__, {:fetch, source}, :infinity)
    end
  end

  # What a child reads when its node lacks the scene its parent pinned.
  defp missing(%Source{name: name}) do
    message = "scene #{name} is not cached on #{node()} and was shipped without its bytes"
    Error.new(:invalid_scene, message)
  end

  @doc """
  The handle of frame `frame` (from 0) of the scene of `source` on this
  node, for `RingTracer.Native`'s scene calls: built on a miss (parsing the
  scene first if it is not cached). Frame 0 is the scene's own handle. A
  frame past the scene's last is an error.
  """
  @spec fetch_frame(Source.t(), non_neg_integer()) ::
          {:ok, reference()} | {:error, Error.t()}
  def fetch_frame(%Source{} = source, 0) do
    with {:ok, scene} <- fetch(source), do: {:ok, scene.ref}
  end

  def fetch_frame(%Source{hash: hash} = source, frame) when is_integer(frame) and frame > 0 do
    case :ets.lookup(@table, {hash, frame}) do
      [{_, ref}] ->
        GenServer.cast(__MODULE__, {:touch_frame, hash, frame})
        {:ok, ref}

      [] ->
        GenServer.call(__MODULE__, {:fetch_frame, source, frame}, :infinity)
    end
  end

  def fetch_frame(%Source{name: name}, frame) do
    message = "scene #{name}: frame #{inspect(frame)} is not a frame number (from 0)"
    {:error, Error.new(:invalid_option, message)}
  end

  @doc """
  Pins the scene of `source` on this node for `owner` (a job's parent)
  until `owner` ends, parsing it first unless it is cached: what a job
  does on each node before starting children there
  (`RingTracer.Job.Host`). A source without its contents (stripped, not
  packed) pins a scene this node holds, or returns `:need_scene`.
  """
  @spec pin(Source.t(), pid()) :: :ok | :need_scene | {:error, String.t()}
  def pin(%Source{} = source, owner) when is_pid(owner) do
    case GenServer.call(__MODULE__, {:pin, source, owner}, :infinity) do
      :ok -> :ok
      :need_scene -> :need_scene
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

  @doc "Sets how many frames of each scene are held (see the module doc), dropping the rest."
  @spec set_max_frames(non_neg_integer()) :: :ok
  def set_max_frames(frames) when is_integer(frames) and frames >= 0,
    do: GenServer.call(__MODULE__, {:max_frames, frames})

  @doc """
  The hashes of the scenes held, and for each its size, how many pins it
  has and which of its frames (but 0) are held.
  """
  @spec info() :: %{
          binary() => %{
            size: non_neg_integer(),
            pins: non_neg_integer(),
            frames: [pos_integer()]
          }
        }
  def info do
    GenServer.call(__MODULE__, :info)
  end

  @impl GenServer
  def init(opts) do
    max =
      Keyword.get_lazy(opts, :max_bytes, fn ->
        Application.get_env(:ring_tracer, :scene_cache_bytes, @default_bytes)
      end)

    max_frames =
      Keyword.get_lazy(opts, :max_frames, fn ->
        Application.get_env(:ring_tracer, :scene_cache_frames, @default_frames)
      end)

    :ets.new(@table, [:named_table, :protected, :set, read_concurrency: true])

    {:ok,
     %{
       max_bytes: max,
       max_frames: max_frames,
       clock: 0,
       entries: %{},
       frames: %{},
       monitors: %{}
     }}
  end

  @impl GenServer
  def handle_call({:fetch, %Source{} = source}, _from, state) do
    case load(state, source) do
      {:ok, scene, state} -> {:reply, {:ok, scene}, evict(state)}
      {:missing, state} -> {:reply, {:error, missing(source)}, state}
      {:error, error, state} -> {:reply, {:error, error}, state}
    end
  end

  def handle_call({:fetch_frame, %Source{hash: hash} = source, frame}, _from, state) do
    case :ets.lookup(@table, {hash, frame}) do
      [{_, ref}] ->
        {:reply, {:ok, ref}, touch_frame(state, hash, frame)}

      [] ->
        case load(state, source) do
          {:ok, scene, state} ->
            case build_frame(scene, frame) do
              {:ok, ref} ->
                :ets.insert(@table, {{hash, frame}, ref})
                state = state |> touch_frame(hash, frame) |> trim_frames(hash) |> evict()
                {:reply, {:ok, ref}, state}

              {:error, error} ->
                {:reply, {:error, error}, evict(state)}
            end

          {:missing, state} ->
            {:reply, {:error, missing(source)}, state}

          {:error, error, state} ->
            {:reply, {:error, error}, state}
        end
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

      {:missing, state} ->
        {:reply, :need_scene, state}

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

  def handle_call({:max_frames, frames}, _from, state) do
    state = %{state | max_frames: frames}
    {:reply, :ok, Enum.reduce(Map.keys(state.frames), state, &trim_frames(&2, &1))}
  end

  def handle_call(:info, _from, state) do
    {:reply,
     Map.new(state.entries, fn {h, e} ->
       frames = state.frames |> Map.get(h, %{}) |> Map.keys() |> Enum.sort()
       {h, %{size: e.size, pins: MapSet.size(e.pins), frames: frames}}
     end), state}
  end

  @impl GenServer
  def handle_cast({:touch, hash}, state), do: {:noreply, touch(state, hash)}

  def handle_cast({:touch_frame, hash, frame}, state),
    do: {:noreply, touch_frame(state, hash, frame)}

  @impl GenServer
  def handle_info({:DOWN, ref, :process, _, _}, state),
    do: {:noreply, state |> drop_pins([ref]) |> evict()}

  @spec load(state(), Source.t()) ::
          {:ok, Scene.t(), state()} | {:missing, state()} | {:error, Error.t(), state()}
  defp load(state, %Source{hash: hash} = source) do
    case :ets.lookup(@table, hash) do
      [{^hash, scene}] ->
        {:ok, scene, touch(state, hash)}

      [] when source.bytes == nil and source.packed == nil ->
        {:missing, state}

      [] ->
        with {:ok, source} <- unpack(source),
             {:ok, scene} <- Scene.from_source(source) do
          {:ok, scene, insert(state, scene)}
        else
          {:error, error} -> {:error, error, state}
        end
    end
  end

  defp unpack(source) do
    case Source.unpack(source) do
      {:ok, source} -> {:ok, source}
      {:error, message} -> {:error, Error.new(:invalid_scene, message)}
    end
  end

  # The scene of `frame` made from the cached scene (`RingTracer.Native.scene_frame/2`).
  defp build_frame(scene, frame) do
    if frame < scene.frames do
      case Native.scene_frame(scene.ref, frame) do
        {:ok, ref} -> {:ok, ref}
        {:error, message} -> {:error, Error.new(:invalid_scene, message)}
      end
    else
      message =
        "scene #{scene.source.name} has #{scene.frames} frame(s) (0 to #{scene.frames - 1}): " <>
          "no frame #{frame}"

      {:error, Error.new(:invalid_option, message)}
    end
  rescue
    e in ErlangError ->
      {:error, Error.new(:invalid_scene, "scene_frame raised: #{Exception.message(e)}")}
  end

  # Fetching a frame uses its scene too. A frame is held only while its
  # scene is.
  defp touch_frame(state, hash, frame) do
    if Map.has_key?(state.entries, hash) and :ets.member(@table, {hash, frame}) do
      %{clock: clock} = state = touch(state, hash)
      frames = Map.update(state.frames, hash, %{frame => clock}, &Map.put(&1, frame, clock))
      %{state | frames: frames}
    else
      state
    end
  end

  # The least recently fetched frames of scene `hash` go while it holds more
  # than `max_frames`.
  defp trim_frames(state, hash) do
    held = Map.get(state.frames, hash, %{})
    excess = map_size(held) - state.max_frames

    if excess > 0 do
      gone = held |> Enum.sort_by(fn {_, used} -> used end) |> Enum.take(excess)
      Enum.each(gone, fn {frame, _} -> :ets.delete(@table, {hash, frame}) end)
      held = Map.drop(held, Enum.map(gone, &elem(&1, 0)))
      %{state | frames: Map.put(state.frames, hash, held)}
    else
      state
    end
  end

  defp drop_frames(state, hash) do
    {held, frames} = Map.pop(state.frames, hash, %{})
    Enum.each(Map.keys(held), &:ets.delete(@table, {hash, &1}))
    %{state | frames: frames}
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
          evict(drop_frames(%{state | entries: Map.delete(state.entries, hash)}, hash))
      end
    else
      state
    end
  end
end
