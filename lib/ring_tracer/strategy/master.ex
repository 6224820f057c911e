defmodule RingTracer.Strategy.Master do
  @moduledoc """
  Master/worker: the parent holds every atom and hands them out one at a
  time. Each child has one atom queued ahead (two in its pipe), and each
  atom result it sends doubles as the request for the next one.
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.Parent
  alias RingTracer.Layout

  @ahead 2

  @impl true
  def initial_atoms(_layout, _index), do: []

  @impl true
  def idle(child), do: %{child | status: :waiting}

  @impl true
  def handle_message(_msg, _child), do: :unhandled

  @impl true
  def parent_start(parent) do
    queue = Enum.to_list(Layout.atoms(parent.spec.layout))
    parent = put_in(parent.strategy_state, queue)

    Enum.reduce(1..@ahead, parent, fn _, p ->
      Enum.reduce(Map.keys(p.children), p, &hand_out(&2, &1))
    end)
  end

  @impl true
  def parent_atom_done(parent, index), do: hand_out(parent, index)

  # A result can arrive from a child that has died since (it was in flight):
  # nothing is handed to the dead; the living keep asking.
  defp hand_out(%{strategy_state: [atom | rest], children: children} = parent, index)
       when is_map_key(children, index) do
    %{Parent.hand_out(parent, index, [atom]) | strategy_state: rest}
  end

  defp hand_out(parent, _index), do: parent
end
