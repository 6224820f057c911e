defmodule RingTracer.Strategy.Steal do
  @moduledoc """
  Random work stealing, as a modern reference point: an idle child asks a
  random sibling it has not asked since its last success for half of that
  sibling's queued atoms. The sibling replies with a hand-over, empty if it
  has nothing to spare. A child that every sibling has refused is finished.
  The order of victims is random but seeded by the child's index, so a job is
  repeatable.
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.Child
  alias RingTracer.Layout

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  @impl true
  def idle(child) do
    victims =
      case child.strategy_state do
        %{victims: v} -> v
        _ -> shuffled_siblings(child)
      end

    case Enum.reject(victims, &(&1 in child.dead)) do
      [] ->
        %{child | status: :finished, strategy_state: %{victims: []}}

      [victim | rest] ->
        child
        |> Child.send_counted(
          elem(child.siblings, victim),
          :offer,
          {:steal, self(), child.index}
        )
        |> Child.event(:steal, victim)
        |> Child.bump(:offers_sent)
        |> Map.merge(%{status: :stealing, strategy_state: %{victims: rest}})
    end
  end

  @impl true
  def handle_message({:steal, thief, thief_index}, child) do
    g = div(length(child.queue), 2)
    {atoms, child} = Child.take_last(child, g)

    child =
      if g > 0, do: Child.bump(child, :offers_consumed), else: Child.bump(child, :offers_passed)

    {:ok,
     child
     |> Child.hand_over(thief, atoms)
     |> Child.event(if(g > 0, do: :give, else: :refuse), thief_index)}
  end

  def handle_message({:handover, _from, []}, child), do: {:ok, idle(child)}

  def handle_message({:handover, _from, atoms}, child),
    do: {:ok, Child.receive_atoms(%{child | strategy_state: %{}}, atoms)}

  def handle_message(_msg, _child), do: :unhandled

  defp shuffled_siblings(child) do
    :rand.seed(:exsss, {child.index + 1, 7, 13})

    0..(tuple_size(child.siblings) - 1)
    |> Enum.to_list()
    |> List.delete(child.index)
    |> Enum.shuffle()
  end
end
