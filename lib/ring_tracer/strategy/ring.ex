defmodule RingTracer.Strategy.Ring do
  @moduledoc """
  The paper's ring: an idle child sends a help offer to its left sibling; a
  sibling with atoms to spare consumes it and hands a speed-proportional
  share directly to the offerer, or passes it on; a child whose own offer
  comes back is finished. The rules are `RingTracer.Ring.HelpOffer` and
  `RingTracer.Ring.Share`.
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.Child
  alias RingTracer.Layout
  alias RingTracer.Ring.HelpOffer

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  @impl true
  def idle(child) do
    seq = (child.strategy_state[:seq] || 0) + 1
    offer = %HelpOffer{origin: child.index, pid: self(), done: child.done, seq: seq}

    child
    |> Child.send_counted(child.left, :offer, {:help_offer, offer})
    |> Child.event(:offer, child.left_index)
    |> Child.bump(:offers_sent)
    |> Map.put(:strategy_state, %{seq: seq, current: seq})
    |> Map.put(:status, :offered)
  end

  @impl true
  def handle_message({:help_offer, %HelpOffer{} = offer}, child) do
    view = %{
      index: child.index,
      remaining: length(child.queue),
      in_flight: length(child.in_flight),
      done: child.done,
      offer_seq: if(child.status == :offered, do: child.strategy_state[:current])
    }

    child =
      case HelpOffer.decide(view, offer) do
        :returned ->
          child |> Child.event(:returned, child.index) |> Map.put(:status, :finished)

        :drop ->
          child

        :pass ->
          child
          |> Child.send_counted(child.left, :offer, {:help_offer, offer})
          |> Child.event(:pass, child.left_index)
          |> Child.bump(:offers_passed)

        {:give, g} ->
          {atoms, child} = Child.take_last(child, g)

          child
          |> Child.hand_over(offer.pid, atoms)
          |> Child.event(:give, offer.origin)
          |> Child.bump(:offers_consumed)
      end

    {:ok, child}
  end

  def handle_message(_msg, _child), do: :unhandled
end
