defmodule RingTracer.Strategy.Ring do
  @moduledoc """
  The paper's ring: an idle child sends a help offer to its left sibling; a
  sibling with atoms to spare consumes it and hands a speed-proportional
  share directly to the offerer, or passes it on; a child whose own offer
  comes back is finished. The rules are `RingTracer.Ring.HelpOffer` and
  `RingTracer.Ring.Share`; so are our two additions, parking (an idle child
  keeps the offers that reach it until its own offer is answered) and
  splicing (offers stop visiting finished children).
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.Child
  alias RingTracer.Layout
  alias RingTracer.Ring.HelpOffer

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  @impl true
  def idle(child) do
    seq = seq(child) + 1

    offer =
      %HelpOffer{origin: child.index, pid: self(), done: child.done, seq: seq, via: self()}
      |> HelpOffer.hop(child.index, child.left_index)

    child
    |> Child.send_counted(child.left, :offer, {:help_offer, offer})
    |> Child.event(:offer, child.left_index)
    |> Child.bump(:offers_sent)
    |> put_strategy(seq: seq, current: seq)
    |> Map.put(:status, :offered)
  end

  @impl true
  def handle_message({:help_offer, %HelpOffer{} = offer}, child), do: {:ok, offer(child, offer)}

  def handle_message({:handover, from, atoms}, child) when is_list(atoms) do
    # Atoms again: the offers parked while we were idle get the share rule.
    {parked, child} = take_parked(child)
    child = Child.receive_atoms(child, atoms)
    {:ok, Enum.reduce(parked, child, &offer(&2, &1, from))}
  end

  def handle_message({:ring_skip, gone, left, left_index}, child) do
    if child.left == gone and left_index not in child.dead do
      {:ok, %{child | left: left, left_index: left_index}}
    else
      {:ok, child}
    end
  end

  def handle_message(_msg, _child), do: :unhandled

  defp offer(child, offer, released_by \\ nil) do
    {remaining, in_flight} = Child.giveable(child)

    view = %{
      index: child.index,
      remaining: remaining,
      in_flight: in_flight,
      done: child.done,
      offer_seq: if(child.status == :offered, do: child.strategy_state[:current])
    }

    case HelpOffer.decide(view, offer) do
      :returned ->
        {parked, child} = take_parked(child)

        child = child |> Child.event(:returned, child.index) |> Map.put(:status, :finished)

        # Every sibling was asked after these offers were made: their origins
        # are finished too.
        Enum.reduce(parked, child, fn o, c ->
          c
          |> Child.send_counted(o.pid, :offer, {:help_offer, o})
          |> Child.event(:back, o.origin)
          |> Child.bump(:offers_passed)
        end)

      :drop ->
        child

      :park ->
        update_in(
          child.strategy_state,
          &Map.update(&1, :parked, [offer], fn p -> p ++ [offer] end)
        )

      :pass ->
        child = if child.status == :finished, do: splice(child, offer), else: child

        {to, to_index} =
          if is_integer(released_by) and released_by != child.index and
               released_by not in child.dead,
             do: {elem(child.siblings, released_by), released_by},
             else: {child.left, child.left_index}

        child
        |> Child.send_counted(
          to,
          :offer,
          {:help_offer, HelpOffer.hop(%{offer | via: self()}, child.index, to_index)}
        )
        |> Child.event(:pass, to_index)
        |> Child.bump(:offers_passed)

      {:give, g} ->
        {atoms, child} = Child.take_last(child, g)

        child
        |> Child.hand_over(offer.pid, atoms)
        |> Child.event(:give, offer.origin)
        |> Child.bump(:offers_consumed)
    end
  end

  # A finished child asks whoever sent it an offer to skip it from now on.
  defp splice(child, %HelpOffer{via: via}) when is_pid(via) and via != self() do
    Child.send_counted(child, via, :control, {:ring_skip, self(), child.left, child.left_index})
  end

  defp splice(child, _offer), do: child

  defp take_parked(child) do
    {parked, rest} = Map.pop(child.strategy_state, :parked, [])
    live = Enum.reject(parked, &(&1.origin in child.dead))
    {live, %{child | strategy_state: rest}}
  end

  defp seq(child), do: child.strategy_state[:seq] || 0

  defp put_strategy(child, kv),
    do: %{child | strategy_state: Map.merge(child.strategy_state, Map.new(kv))}
end
