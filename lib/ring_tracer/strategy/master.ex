defmodule RingTracer.Strategy.Master do
  @moduledoc """
  Master/worker: the parent holds every atom and hands them out one at a
  time. Each child has one atom queued ahead (two in its pipe), and each
  atom result it sends doubles as the request for the next one. In a job
  of several frames, the parent queues each frame's atoms as it is
  released, and a child that asked while the queue was empty gets the new
  frame's first atoms.
  """
  use RingTracer.Strategy

  alias RingTracer.Layout

  @ahead 2

  @impl true
  def initial_atoms(_layout, _index, _options), do: []

  # Idle, a child waits for the parent's next atom.
  @impl true
  def idle(_view, state), do: {state, []}

  # The parent's state: the atoms not handed out yet.
  @impl true
  def parent_start(view, _options) do
    queue = Enum.to_list(Layout.atoms(view.spec.layout))
    rounds = for _ <- 1..@ahead, i <- Map.keys(view.children), do: i
    {queue, effects} = Enum.reduce(rounds, {queue, []}, &hand_out(&2, &1, view))
    {queue, Enum.reverse(effects)}
  end

  @impl true
  def parent_atom_done(view, queue, index), do: hand_out({queue, []}, index, view)

  # A result can arrive from a child that has died since (it was in flight):
  # nothing is handed to the dead; the living keep asking.
  defp hand_out({[atom | rest], effects}, index, view) when is_map_key(view.children, index),
    do: {rest, [{:hand_out, index, [atom]} | effects]}

  defp hand_out(acc, _index, _view), do: acc
end
