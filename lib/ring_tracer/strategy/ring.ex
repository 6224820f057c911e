defmodule RingTracer.Strategy.Ring do
  @moduledoc """
  The paper's ring: an idle child sends a help offer to its left sibling; a
  sibling with atoms to spare consumes it and hands a share sized to the
  children's speeds directly to the offerer, or passes it on; a child whose
  own offer comes back is finished. The rules are `RingTracer.Ring.HelpOffer`
  and `RingTracer.Ring.Share`; so are our additions: speeds measured in
  kernel work per busy microsecond, a share planned with one more helper
  than the two children (gossip: offers carry the fastest siblings heard
  of), parking (an idle child keeps the offers that reach it until its own
  offer is answered), holding (in a large ring, an offer that walked far
  waits for a child about to run out and leaves with that child's own
  offer, in one message) and splicing (offers stop visiting finished
  children).
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

    rate = Child.rate(child)
    {heard, child} = hear(child, rate, [])

    offer =
      %HelpOffer{
        origin: child.index,
        pid: self(),
        seq: seq,
        via: self(),
        rate: rate,
        atom_us: Child.mean_atom_us(child),
        heard: heard
      }
      |> HelpOffer.hop(child.index, child.left_index)

    # Offers held while we traced our last atom leave with ours, in one message.
    {held, child} = take_offers(child, :held)

    held =
      Enum.map(
        held,
        &HelpOffer.hop(%{&1 | via: self(), heard: heard}, child.index, child.left_index)
      )

    child
    |> Child.send_counted(child.left, :offer, offers_message([offer | held]))
    |> Child.event(:offer, child.left_index)
    |> then(&Enum.reduce(held, &1, fn _, c -> Child.event(c, :pass, child.left_index) end))
    |> Child.bump(:offers_sent)
    |> put_strategy(seq: seq, current: seq)
    |> Map.put(:status, :offered)
  end

  @impl true
  def handle_message({:help_offer, %HelpOffer{} = offer}, child),
    do: {:ok, child |> offer(offer) |> flush()}

  def handle_message({:help_offers, offers}, child) when is_list(offers),
    do: {:ok, offers |> Enum.reduce(child, &offer(&2, &1)) |> flush()}

  def handle_message({:handover, from, atoms}, child) when is_list(atoms) do
    # Atoms again: the offers parked while we were idle (or held while we
    # traced our last atom) get the share rule.
    {parked, child} = take_offers(child, :parked)
    {held, child} = take_offers(child, :held)
    child = Child.receive_atoms(child, atoms)
    {:ok, (parked ++ held) |> Enum.reduce(child, &offer(&2, &1, from)) |> flush()}
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

    # What the offer heard goes into what we know; what we know goes on with
    # the offer.
    rate = Child.rate(child)
    {heard, child} = hear(child, rate, offer.heard)
    offer = %{offer | heard: heard}

    view = %{
      index: child.index,
      remaining: remaining,
      in_flight: in_flight,
      rate: rate,
      heard: heard,
      ring_size: tuple_size(child.siblings) - length(child.dead),
      offer_seq: if(child.status == :offered, do: child.strategy_state[:current]),
      remaining_us: if(in_flight > 0, do: Child.expected_remaining_us(child)),
      hold_after: child.spec.hold_after
    }

    case HelpOffer.decide(view, offer) do
      :returned ->
        {parked, child} = take_offers(child, :parked)

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
        keep(child, :parked, offer)

      :hold ->
        keep(child, :held, %{offer | held: true})

      :pass ->
        child = if child.status == :finished, do: splice(child, offer), else: child

        {to, to_index} =
          if is_integer(released_by) and released_by != child.index and
               released_by not in child.dead,
             do: {elem(child.siblings, released_by), released_by},
             else: {child.left, child.left_index}

        child
        |> keep(:outbox, {to, HelpOffer.hop(%{offer | via: self()}, child.index, to_index)})
        |> Child.event(:pass, to_index)

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

  defp keep(child, key, item),
    do: update_in(child.strategy_state, &Map.update(&1, key, [item], fn l -> l ++ [item] end))

  # One offer travels alone, several in one message.
  defp offers_message([offer]), do: {:help_offer, offer}
  defp offers_message(offers), do: {:help_offers, offers}

  defp take(child, key) do
    {list, rest} = Map.pop(child.strategy_state, key, [])
    {list, %{child | strategy_state: rest}}
  end

  # Parked or held offers, less those whose origin has died since.
  defp take_offers(child, key) do
    {offers, child} = take(child, key)
    {Enum.reject(offers, &(&1.origin in child.dead)), child}
  end

  # Offers passed on while handling one message leave together: one message
  # per sibling they go to.
  defp flush(child) do
    {outbox, child} = take(child, :outbox)

    outbox
    |> Enum.group_by(&elem(&1, 0), &elem(&1, 1))
    |> Enum.reduce(child, fn {to, offers}, c ->
      c
      |> Child.send_counted(to, :offer, offers_message(offers))
      |> Child.bump(:offers_passed)
    end)
  end

  defp seq(child), do: child.strategy_state[:seq] || 0

  # What a child has heard of the fastest siblings, with `news` and its own
  # newest `rate` added and dead siblings left out; kept, and returned.
  defp hear(child, rate, news) do
    mine = {rate, child.index, child.done}
    known = child.strategy_state[:heard] || []

    dead? = fn {_, i, _} -> i in child.dead end
    heard = HelpOffer.learn(Enum.reject(known, dead?), Enum.reject([mine | news], dead?))

    {heard, put_strategy(child, heard: heard)}
  end

  defp put_strategy(child, kv),
    do: %{child | strategy_state: Map.merge(child.strategy_state, Map.new(kv))}
end
