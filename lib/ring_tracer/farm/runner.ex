defmodule RingTracer.Farm.Runner do
  @moduledoc false
  # One running farm job, on the head: parses the job's scene from its
  # bytes, starts one ring (`RingTracer.render_sequence/2`) over the workers
  # the head gave it for the frames not done yet, and, as each frame
  # completes, writes its file into the head's folder (atomically), records
  # it done (`RingTracer.Farm.Store`), tells the head and only then lets the
  # frame leave the ring's window (`ack: true`). The head tells it of
  # workers gained (`{:grow, node, slots}`) and let go (`{:release, node}`);
  # it tells the head `{:runner_frame, id, n}`, the ring's progress
  # (`{:runner_progress, id, atoms_done, atoms_total}`), on a head with a
  # dashboard its preview's address (`{:runner_preview, id, url}`) and,
  # last, `{:runner_end, id, self(), outcome}`. Stopped by its supervisor (the
  # head's `DynamicSupervisor.terminate_child/2`), it cancels its ring
  # before it exits.

  use GenServer, restart: :temporary

  alias RingTracer.{Error, Image, Scene}
  alias RingTracer.Farm.{Job, Store}

  # Options the farm sets itself, for the workers it chose and the frames' format.
  @farm_set [:nodes, :local, :children_per_node, :children, :frames, :window, :ack, :pixels]

  @type outcome :: :done | {:failed, String.t()} | {:retry, String.t()} | {:lost, String.t()}

  defmodule State do
    @moduledoc false
    @enforce_keys [:job, :head, :dir]
    defstruct [:job, :head, :dir, :handle, :elastic, nodes: []]

    @type t :: %__MODULE__{
            job: RingTracer.Farm.Job.t(),
            head: pid(),
            dir: term(),
            handle: %{id: reference(), pid: pid()} | nil,
            elastic: pid() | nil,
            nodes: [node()]
          }
  end

  @doc false
  @spec start_link({Job.t(), [{node(), pos_integer()}], term(), pid()}) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  @doc "The options a submission may not set: the farm sets them."
  @spec farm_set() :: [atom()]
  def farm_set, do: @farm_set

  @impl true
  def init({%Job{} = job, workers, dir, head}) do
    # terminate/2 runs when the head stops this runner.
    Process.flag(:trap_exit, true)

    {:ok, %State{job: job, head: head, dir: dir, nodes: Enum.map(workers, &elem(&1, 0))},
     {:continue, {:start, workers}}}
  end

  @impl true
  def handle_continue({:start, workers}, %State{job: job} = state) do
    remaining = job.frames -- Store.done(job.id)

    with {:remaining, [_ | _]} <- {:remaining, remaining},
         {:ok, scene} <- Scene.from_source(job.source),
         {:ok, handle} <- start(scene, job, workers, remaining, preview(state)) do
      {:noreply, %{state | handle: handle}}
    else
      {:remaining, []} -> finish(state, :done)
      {:error, %Error{} = error} -> finish(state, outcome(error))
    end
  end

  @impl true
  def handle_info({RingTracer, id, {:frame, n, frame}}, %State{handle: %{id: id}} = state) do
    %State{job: job, dir: dir, handle: handle} = state
    name = Job.frame_file(job, n)

    case Image.write(name, frame.width, frame.height, frame.pixels,
           in: dir,
           mode: 0o600,
           format: frame.pixel_format
         ) do
      :ok ->
        :ok = Store.frame_done(job.id, n)
        send(state.head, {:runner_frame, job.id, n})
        RingTracer.ack_frame(handle, n)
        {:noreply, state}

      {:error, %Error{message: message}} ->
        RingTracer.cancel(handle)
        finish(state, {:failed, "the head could not store frame #{n}: #{message}"})
    end
  end

  def handle_info({RingTracer, id, {:progress, done, total}}, %State{handle: %{id: id}} = state) do
    send(state.head, {:runner_progress, state.job.id, done, total})
    {:noreply, state}
  end

  def handle_info({RingTracer, id, {:ok, _result}}, %State{handle: %{id: id}} = state),
    do: finish(state, :done)

  def handle_info({RingTracer, id, {:error, error}}, %State{handle: %{id: id}} = state),
    do: finish(state, outcome(error))

  def handle_info({:grow, node, slots}, %State{} = state) do
    state = %{state | nodes: Enum.uniq(state.nodes ++ [node])}
    {:noreply, elastic(state, {:grow, node, slots})}
  end

  def handle_info({:release, node}, %State{} = state) do
    state = %{state | nodes: List.delete(state.nodes, node)}
    {:noreply, elastic(state, {:shrink, node})}
  end

  def handle_info(_other, state), do: {:noreply, state}

  # On a head with a dashboard, the ring's live preview: on loopback, with
  # its own token, gone with this runner (its owner).
  defp preview(%State{job: job, head: head}) do
    with true <- RingTracer.Farm.Dashboard.running?(),
         {:ok, preview} <- RingTracer.Preview.start() do
      send(preview.pid, {:owner, self()})
      send(head, {:runner_preview, job.id, preview.url})
      [preview: preview]
    else
      _ -> []
    end
  end

  @impl true
  def terminate(_reason, %State{handle: handle}) do
    if handle, do: RingTracer.cancel(handle)
    :ok
  end

  defp start(scene, job, workers, remaining, preview) do
    slots = workers |> Enum.map(&elem(&1, 1)) |> Enum.min()

    opts =
      Keyword.drop(job.options, @farm_set) ++
        [
          nodes: Enum.map(workers, &elem(&1, 0)),
          local: false,
          children_per_node: slots,
          frames: remaining,
          ack: true,
          # 8-bit when the frames are PNGs
          pixels: RingTracer.Pixels.for_files([Job.frame_file(job, 1)])
        ] ++ preview

    RingTracer.render_sequence(scene, opts)
  end

  # The elastic ring's calls (`RingTracer.grow/4`, `shrink/3`) are made by a
  # process of the runner's, one at a time in the order the head asked, so
  # that the runner goes on storing frames during a grow, and a worker let
  # go while its grow runs leaves after it. It ends with the runner.
  defp elastic(%State{handle: nil} = state, _call), do: state

  defp elastic(%State{elastic: nil, handle: handle} = state, call) do
    runner = self()

    pid =
      spawn(fn ->
        ref = Process.monitor(runner)
        elastic_loop(handle, ref)
      end)

    elastic(%{state | elastic: pid}, call)
  end

  defp elastic(%State{elastic: pid} = state, call) do
    send(pid, call)
    state
  end

  defp elastic_loop(handle, ref) do
    receive do
      {:grow, node, slots} -> _ = RingTracer.grow(handle, node, slots)
      {:shrink, node} -> _ = RingTracer.shrink(handle, node)
      {:DOWN, ^ref, _, _, _} -> exit(:normal)
    end

    elastic_loop(handle, ref)
  end

  # A scene or an option that is not valid fails the job for good; a ring
  # whose every child went (its workers lost) waits for others, and is no
  # failure of the job's; anything else is worth another go or two.
  defp outcome(%Error{reason: reason, message: message})
       when reason in [:invalid_scene, :invalid_option, :file],
       do: {:failed, message}

  defp outcome(%Error{message: "every child exited" <> _ = message}), do: {:lost, message}
  defp outcome(%Error{message: message}), do: {:retry, message}

  defp finish(%State{job: job, head: head} = state, outcome) do
    send(head, {:runner_end, job.id, self(), outcome})
    {:stop, :normal, state}
  end
end
