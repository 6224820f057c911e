defmodule RingTracer.Strategy.Master do
  @moduledoc false
  # Master/worker: the parent holds every atom and hands them out one at a
  # time. Each child has one atom queued ahead (two in its pipe), and each
  # atom result it sends doubles as the request for the next one. In a job
  # of several frames, the parent queues each frame's atoms as it is
  # released, and a child that asked while the queue was empty gets the new
  # frame's first atoms. A child that joins a running job asks for two
  # atoms as the first ones did.

  use RingTracer.Strategy

  @impl true
  def options(options, _layout), do: RingTracer.Strategy.no_options(options, :master)

  alias RingTracer.Layout

  @ahead 2

  @impl true
  def initial_atoms(_layout, _index, _options), do: []

  # Idle, a child waits for the parent's next atom.
  @impl true
  def idle(_view, state), do: {state, []}

  # The parent's state: the atoms not handed out yet, and the children that
  # asked for one while there was none (once per request).
  @impl true
  def parent_start(view, _options) do
    queue = Enum.to_list(Layout.frame_atoms(view.spec.layout, 0))
    asking = for _ <- 1..@ahead, i <- Map.keys(view.children), do: i
    serve(%{queue: queue, owed: []}, asking, view)
  end

  @impl true
  def parent_atom_done(view, state, index), do: serve(state, [index], view)

  # Children that joined ask, as the first ones did, for two atoms each.
  @impl true
  def parent_joined(view, state, joined),
    do: serve(state, for(_ <- 1..@ahead, i <- joined, do: i), view)

  @impl true
  def parent_frame(view, state, frame) do
    queue = state.queue ++ Enum.to_list(Layout.frame_atoms(view.spec.layout, frame))
    serve(%{state | queue: queue, owed: []}, state.owed, view)
  end

  defp serve(state, asking, view) do
    {state, effects} = Enum.reduce(asking, {state, []}, &hand_out(&2, &1, view))
    {state, Enum.reverse(effects)}
  end

  # A result can arrive from a child that has died since (it was in flight):
  # nothing is handed to the dead; the living keep asking.
  defp hand_out({state, effects}, index, view) when is_map_key(view.children, index) do
    case state.queue do
      [atom | rest] -> {%{state | queue: rest}, [{:hand_out, index, [atom]} | effects]}
      [] -> {%{state | owed: state.owed ++ [index]}, effects}
    end
  end

  defp hand_out(acc, _index, _view), do: acc
end
