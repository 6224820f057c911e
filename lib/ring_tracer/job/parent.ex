defmodule RingTracer.Job.Parent do
  @moduledoc """
  The parent of one render job: it starts the children, links them in a
  ring, receives every atom's pixels, and ends the job.

  The job is complete when the parent holds every atom exactly once; that,
  not the ring's tokens, is the termination test, because atoms handed over
  between children may still be in flight when an offer returns. An atom
  that arrives twice is counted once. On completion the parent sends each
  child the stop message, waits until every child has stopped (a child kills
  its grandchild first), sends the result to the caller and stops: no process
  of the job outlives it.

  If the caller dies, the job stops. If a child dies or an atom fails for
  good, the job fails with the reason.
  """
  use GenServer, restart: :temporary

  alias RingTracer.Layout
  alias RingTracer.Job.{Child, Spec}

  @doc false
  @spec start(Spec.t()) :: DynamicSupervisor.on_start_child()
  def start(%Spec{} = spec) do
    DynamicSupervisor.start_child(RingTracer.Names.jobs(), {__MODULE__, spec})
  end

  @doc false
  @spec start_link(Spec.t()) :: GenServer.on_start()
  def start_link(spec), do: GenServer.start_link(__MODULE__, spec)

  @impl GenServer
  def init(%Spec{} = spec) do
    Process.monitor(spec.caller)

    state = %{
      spec: spec,
      started: System.monotonic_time(:microsecond),
      children: %{},
      monitors: %{},
      results: %{},
      missing: Layout.atom_count(spec.layout),
      stopping: nil
    }

    {:ok, state, {:continue, :start_ring}}
  end

  @impl GenServer
  def handle_continue(:start_ring, state) do
    %Spec{layout: layout, nodes: nodes} = state.spec
    nodes = if nodes == [], do: [node()], else: nodes
    n = layout.children

    started =
      Enum.reduce_while(0..(n - 1), {:ok, []}, fn i, {:ok, acc} ->
        node = Enum.at(nodes, rem(i, length(nodes)))

        case Child.start(node, state.spec, i, self()) do
          {:ok, pid} -> {:cont, {:ok, [{i, pid} | acc]}}
          other -> {:halt, {:error, "could not start child #{i} on #{node}: #{inspect(other)}"}}
        end
      end)

    case started do
      {:ok, list} ->
        children = Map.new(list)
        monitors = Map.new(list, fn {i, pid} -> {Process.monitor(pid), i} end)

        for {i, pid} <- children do
          send(pid, {:ring, Map.fetch!(children, rem(i - 1 + n, n))})
        end

        {:noreply, %{state | children: children, monitors: monitors}}

      {:error, message} ->
        fail(state, message)
    end
  end

  @impl GenServer
  def handle_info({:atom_done, _child, atom, pixels, _rays, _us}, %{stopping: nil} = state) do
    {_first, count} = Layout.span(state.spec.layout, atom)

    cond do
      Map.has_key?(state.results, atom) ->
        {:noreply, state}

      byte_size(pixels) != count * 12 ->
        fail(
          state,
          "atom #{atom} came back with #{byte_size(pixels)} bytes, expected #{count * 12}"
        )

      true ->
        state = %{
          state
          | results: Map.put(state.results, atom, pixels),
            missing: state.missing - 1
        }

        if state.missing == 0, do: stop_children(state), else: {:noreply, state}
    end
  end

  def handle_info({:atom_failed, child, atom, message}, %{stopping: nil} = state) do
    fail(state, "atom #{atom} failed on child #{child}: #{message}")
  end

  def handle_info({:child_failed, child, message}, %{stopping: nil} = state) do
    fail(state, "child #{child} failed: #{message}")
  end

  def handle_info({:child_stopped, index, stats}, %{stopping: stopping} = state)
      when is_map(stopping) do
    state = %{state | stopping: %{stopping | stats: Map.put(stopping.stats, index, stats)}}
    {:noreply, state}
  end

  def handle_info({:DOWN, ref, :process, _pid, reason}, state) do
    case Map.pop(state.monitors, ref) do
      {nil, _} ->
        # The caller went away: nobody wants the image.
        if state.stopping, do: {:noreply, state}, else: cancel(state)

      {index, monitors} ->
        state = %{state | monitors: monitors}

        cond do
          state.stopping != nil and monitors == %{} -> finish(state)
          state.stopping != nil -> {:noreply, state}
          true -> fail(state, "child #{index} exited: #{inspect(reason)}")
        end
    end
  end

  def handle_info(_other, state), do: {:noreply, state}

  defp stop_children(state) do
    for {_i, pid} <- state.children, do: send(pid, {:stop, self()})
    state = %{state | stopping: %{outcome: :ok, stats: %{}}}
    if state.monitors == %{}, do: finish(state), else: {:noreply, state}
  end

  defp fail(state, message) do
    for {_i, pid} <- state.children, do: send(pid, {:stop, self()})
    state = %{state | stopping: %{outcome: {:error, message}, stats: %{}}}
    if state.monitors == %{}, do: finish(state), else: {:noreply, state}
  end

  defp cancel(state) do
    for {_i, pid} <- state.children, do: Process.exit(pid, :kill)
    {:stop, :normal, state}
  end

  defp finish(state) do
    %{spec: spec, stopping: stopping} = state
    elapsed = System.monotonic_time(:microsecond) - state.started

    reply =
      case stopping.outcome do
        :ok ->
          pixels =
            spec.layout
            |> Layout.atoms()
            |> Enum.map(&Map.fetch!(state.results, &1))
            |> IO.iodata_to_binary()

          children = for i <- 0..(spec.layout.children - 1), do: Map.get(stopping.stats, i)
          {:ok, %{pixels: pixels, elapsed_us: elapsed, children: children}}

        {:error, message} ->
          {:error, message}
      end

    send(spec.caller, {RingTracer, spec.id, reply})
    {:stop, :normal, state}
  end
end
