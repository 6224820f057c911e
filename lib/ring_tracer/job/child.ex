defmodule RingTracer.Job.Child do
  @moduledoc """
  A child: one member of the ring, owner of one strip of the image.

  Started by the job's parent under `RingTracer.Children` on the node the
  child runs on (a supervision tree cannot span nodes; the child's life is
  tied to its parent's by a monitor). It fetches the parsed scene from its
  node's `RingTracer.SceneCache`, then waits for `{:ring, left}` from the
  parent, naming its left sibling.

  Then, as the paper has it:

    * it spawns a grandchild and keeps two atoms in its pipe (one being
      traced, one queued), so the grandchild never waits;
    * every traced atom's pixels go to the parent at once;
    * when it holds no more atoms it sends a help offer
      (`RingTracer.Ring.HelpOffer`) to its left sibling;
    * an offer from a sibling is consumed (atoms handed over directly to the
      offerer) or passed on to the left, by `RingTracer.Ring.HelpOffer.decide/2`;
    * when its own offer comes back it is finished and waits for the
      parent's stop message.

  A grandchild that dies is restarted and its atoms retried, at most
  three times per atom; then the child reports the atom as failed to
  the parent, which fails the job.
  """
  use GenServer, restart: :temporary

  alias RingTracer.{Layout, SceneCache}
  alias RingTracer.Job.{Grandchild, Spec}
  alias RingTracer.Ring.HelpOffer

  @pipe_depth 2
  @max_attempts 3

  @doc false
  @spec start(node(), Spec.t(), non_neg_integer(), pid()) :: DynamicSupervisor.on_start_child()
  def start(node, %Spec{} = spec, index, parent) do
    DynamicSupervisor.start_child(
      RingTracer.Names.children(node),
      {__MODULE__, {spec, index, parent}}
    )
  end

  @doc false
  @spec start_link({Spec.t(), non_neg_integer(), pid()}) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  @impl GenServer
  def init({%Spec{} = spec, index, parent}) do
    Process.flag(:trap_exit, true)
    Process.monitor(parent)

    state = %{
      spec: spec,
      index: index,
      parent: parent,
      left: nil,
      scene: nil,
      grandchild: nil,
      queue: Layout.strip(spec.layout, index),
      in_flight: [],
      attempts: %{},
      done: 0,
      offer_seq: 0,
      current_offer: nil,
      status: :waiting,
      stats: %{
        index: index,
        node: node(),
        own: spec.layout.atoms_per_child,
        given: 0,
        received: 0,
        handovers: 0,
        traced: 0,
        offers_sent: 0,
        offers_passed: 0,
        offers_consumed: 0,
        grandchild_restarts: 0,
        busy_us: 0,
        rays: %{eye: 0, eye_hits: 0, reflected: 0, refracted: 0, shadow: 0}
      }
    }

    {:ok, state, {:continue, :scene}}
  end

  @impl GenServer
  def handle_continue(:scene, state) do
    case SceneCache.fetch(state.spec.source) do
      {:ok, scene} ->
        {:noreply, %{state | scene: scene}}

      {:error, error} ->
        send(state.parent, {:child_failed, state.index, error.message})
        {:stop, :normal, state}
    end
  end

  @impl GenServer
  def handle_info({:ring, left}, state) do
    state = %{state | left: left, status: :working} |> spawn_grandchild() |> fill_pipe()
    {:noreply, maybe_offer(state)}
  end

  def handle_info({:traced, gc, atom, pixels, rays, us}, %{grandchild: gc} = state) do
    send(state.parent, {:atom_done, state.index, atom, pixels, rays, us})

    stats = %{
      state.stats
      | traced: state.stats.traced + 1,
        busy_us: state.stats.busy_us + us,
        rays: Map.merge(state.stats.rays, rays, fn _, a, b -> a + b end)
    }

    state = %{
      state
      | in_flight: List.delete(state.in_flight, atom),
        attempts: Map.delete(state.attempts, atom),
        done: state.done + 1,
        stats: stats
    }

    {:noreply, state |> fill_pipe() |> maybe_offer()}
  end

  def handle_info({:atom_failed, gc, atom, message}, %{grandchild: gc} = state) do
    {:noreply, retry(state, [atom], message)}
  end

  def handle_info({:help_offer, %HelpOffer{} = offer}, state) do
    view = %{
      index: state.index,
      remaining: length(state.queue),
      in_flight: length(state.in_flight),
      done: state.done,
      offer_seq: state.current_offer
    }

    case HelpOffer.decide(view, offer) do
      :returned ->
        {:noreply, %{state | status: :finished, current_offer: nil}}

      :drop ->
        {:noreply, state}

      :pass ->
        send(state.left, {:help_offer, offer})
        {:noreply, update_in(state.stats.offers_passed, &(&1 + 1))}

      {:give, g} ->
        {keep, give} = HelpOffer.split_queue(state.queue, g)
        hand_over(state, offer.pid, {:handover, state.index, give})

        stats = %{
          state.stats
          | given: state.stats.given + g,
            offers_consumed: state.stats.offers_consumed + 1
        }

        {:noreply, %{state | queue: keep, stats: stats}}
    end
  end

  def handle_info({:handover, _from, atoms}, state) do
    state = %{
      state
      | queue: state.queue ++ atoms,
        status: :working,
        current_offer: nil,
        stats: %{
          state.stats
          | received: state.stats.received + length(atoms),
            handovers: state.stats.handovers + 1
        }
    }

    {:noreply, state |> fill_pipe() |> maybe_offer()}
  end

  def handle_info({:stop, parent}, %{parent: parent} = state) do
    send(parent, {:child_stopped, state.index, state.stats})
    {:stop, :normal, state}
  end

  def handle_info({:DOWN, _ref, :process, parent, _reason}, %{parent: parent} = state) do
    {:stop, :normal, state}
  end

  def handle_info({:EXIT, gc, reason}, %{grandchild: gc} = state) when reason != :normal do
    state = %{
      state
      | grandchild: nil,
        stats: %{state.stats | grandchild_restarts: state.stats.grandchild_restarts + 1}
    }

    {:noreply,
     retry(spawn_grandchild(state), state.in_flight, "grandchild exited: #{inspect(reason)}")}
  end

  def handle_info(_other, state), do: {:noreply, state}

  @impl GenServer
  def terminate(_reason, state) do
    if state.grandchild, do: stop_grandchild(state.grandchild)
    :ok
  end

  # Re-sends the given atoms to a (new) grandchild, or gives up on an atom
  # that has failed too often.
  defp retry(state, atoms, message) do
    {state, failed} =
      Enum.reduce(atoms, {state, nil}, fn atom, {st, failed} ->
        n = Map.get(st.attempts, atom, 1)

        if n >= @max_attempts do
          {st, failed || {atom, message}}
        else
          {%{st | attempts: Map.put(st.attempts, atom, n + 1)}, failed}
        end
      end)

    case failed do
      nil ->
        state = ensure_grandchild(state)
        Enum.each(atoms, &send(state.grandchild, {:trace, &1}))
        state

      {atom, message} ->
        send(state.parent, {:atom_failed, state.index, atom, message})
        state
    end
  end

  defp ensure_grandchild(%{grandchild: nil} = state), do: spawn_grandchild(state)
  defp ensure_grandchild(state), do: state

  defp spawn_grandchild(state) do
    gc = Grandchild.start_link(state.scene.ref, state.spec.settings, state.spec.layout)
    %{state | grandchild: gc}
  end

  defp stop_grandchild(gc) do
    ref = Process.monitor(gc)
    Process.unlink(gc)
    Process.exit(gc, :kill)

    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    end
  end

  defp fill_pipe(%{queue: [atom | rest], in_flight: in_flight} = state)
       when length(in_flight) < @pipe_depth do
    send(state.grandchild, {:trace, atom})
    fill_pipe(%{state | queue: rest, in_flight: in_flight ++ [atom]})
  end

  defp fill_pipe(state), do: state

  defp maybe_offer(%{queue: [], in_flight: [], status: :working} = state) do
    seq = state.offer_seq + 1
    offer = %HelpOffer{origin: state.index, pid: self(), done: state.done, seq: seq}
    send(state.left, {:help_offer, offer})

    %{
      state
      | offer_seq: seq,
        current_offer: seq,
        status: :offered,
        stats: %{state.stats | offers_sent: state.stats.offers_sent + 1}
    }
  end

  defp maybe_offer(state), do: state

  defp hand_over(%{spec: %Spec{handover_delay: 0}}, pid, msg), do: send(pid, msg)

  defp hand_over(%{spec: %Spec{handover_delay: ms}}, pid, msg),
    do: Process.send_after(pid, msg, ms)
end
