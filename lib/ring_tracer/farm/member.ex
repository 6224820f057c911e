defmodule RingTracer.Farm.Member do
  @moduledoc false
  # A worker's membership of a farm: connects to the head, joins it (its
  # tags and slots) and watches it; when the head goes, it tries again
  # every `@retry_ms` until the head is back, so a restarted head finds its
  # workers again by itself. The children it hosts are the jobs' own, under
  # `RingTracer.Children` as for any render.
  #
  # Builds (RingTracer.Cluster.Build) are checked both ways: the worker asks
  # the head's build before it joins, and tells its own in the join, which a
  # head of another build refuses, naming both builds. The worker logs that once
  # (again only if the head's answer changes) and tries again every
  # `@refused_ms`, so that the head, or this node, upgraded to the same
  # build finds it without a restart.

  use GenServer
  require Logger

  alias RingTracer.Cluster.Build
  alias RingTracer.Error
  alias RingTracer.Names

  @retry_ms 500
  @refused_ms 5_000
  @call_ms 5_000

  defmodule State do
    @moduledoc false
    @enforce_keys [:head, :tags, :slots]
    defstruct [:head, :tags, :slots, speed: 1, ref: nil, joined: 0, refused: nil]

    @type t :: %__MODULE__{
            head: node(),
            tags: [String.t()],
            slots: pos_integer(),
            speed: number(),
            ref: reference() | nil,
            joined: non_neg_integer(),
            refused: String.t() | nil
          }
  end

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: Names.farm_member())

  @doc false
  @spec child_spec(keyword()) :: Supervisor.child_spec()
  def child_spec(opts),
    do: %{id: __MODULE__, start: {__MODULE__, :start_link, [opts]}, restart: :transient}

  @doc "Whether this member has joined its head now."
  @spec joined?() :: boolean()
  def joined? do
    GenServer.call(Names.farm_member(), :joined?)
  catch
    :exit, _ -> false
  end

  @impl true
  def init(opts) do
    state = %State{
      head: opts[:head],
      tags: opts[:tags] || [],
      slots: opts[:slots],
      speed: opts[:speed] || 1
    }

    {:ok, state, {:continue, :join}}
  end

  @impl true
  def handle_continue(:join, state), do: {:noreply, join(state)}

  @impl true
  def handle_info(:join, state), do: {:noreply, join(state)}

  def handle_info({:DOWN, ref, :process, _, reason}, %State{ref: ref} = state) do
    Logger.warning("farm: lost the head #{state.head} (#{inspect(reason)}); joining again")
    Process.send_after(self(), :join, @retry_ms)
    {:noreply, %{state | ref: nil}}
  end

  def handle_info(_other, state), do: {:noreply, state}

  @impl true
  def handle_call(:joined?, _from, state), do: {:reply, state.ref != nil, state}

  defp join(%State{ref: nil, head: head} = state) do
    about = %{tags: state.tags, slots: state.slots, speed: state.speed, build: Build.identity()}

    with true <- Node.connect(head),
         :ok <- same_build(head),
         :ok <- call(head, {:join, node(), about, self()}) do
      if state.joined == 0, do: Logger.info("farm: joined #{head}")
      ref = Process.monitor(Names.farm_head(head))
      %{state | ref: ref, joined: state.joined + 1, refused: nil}
    else
      {:error, %Error{message: message}} ->
        if message != state.refused,
          do: Logger.error("farm: cannot join #{head}: #{message}")

        Process.send_after(self(), :join, @refused_ms)
        %{state | refused: message}

      _ ->
        Process.send_after(self(), :join, @retry_ms)
        state
    end
  end

  defp join(state), do: state

  defp same_build(head) do
    case Build.check(head, timeout: @call_ms) do
      :ok -> :ok
      {:error, %Error{} = error} -> {:error, error}
      {:error, {:call, _}} -> :unreachable
    end
  end

  defp call(head, message) do
    GenServer.call(Names.farm_head(head), message, @call_ms)
  catch
    :exit, _ -> :unreachable
  end
end
