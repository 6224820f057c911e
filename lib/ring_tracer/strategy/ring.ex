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
  offer, in one message), splicing (offers stop visiting finished
  children) and aiming (on strips, an idle child's offer goes straight to
  the sibling it expects to stay busy longest: `RingTracer.Ring.Aim`).
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.{Child, Parent}
  alias RingTracer.Layout
  alias RingTracer.Ring.{Aim, HelpOffer}

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  # The parent's side of aiming: a preview of each atom's work, traced beside
  # the children's first atoms where the kernel can make one, then one board
  # (`RingTracer.Ring.Aim.board/4`) once every child has sent an atom.
  @impl true
  def parent_start(%{spec: %{aim: true, kernel: {kernel, opts}} = spec} = parent) do
    parent =
      if function_exported?(kernel, :atom_work, 2) do
        me = self()

        Parent.start_helper(parent, fn ->
          send(me, {:atom_work, spec.id, kernel.atom_work(spec, opts)})
        end)
      else
        parent
      end

    %{parent | strategy_state: %{work: nil, heard_from: MapSet.new(), board: false}}
  end

  def parent_start(parent), do: parent

  @impl true
  def parent_atom_done(%{strategy_state: %{board: false} = board} = parent, index),
    do:
      board(%{parent | strategy_state: %{board | heard_from: MapSet.put(board.heard_from, index)}})

  def parent_atom_done(parent, _index), do: parent

  @impl true
  def parent_info(%{strategy_state: %{board: false} = board} = parent, {:atom_work, id, result})
      when id == parent.spec.id do
    case result do
      {:ok, work} -> board(%{parent | strategy_state: %{board | work: work}})
      # No preview: no board; offers still carry the loads children report.
      {:error, _} -> %{parent | strategy_state: %{board | board: true}}
    end
  end

  def parent_info(parent, _msg), do: parent

  defp board(%{strategy_state: %{work: work, heard_from: from} = board} = parent)
       when work != nil do
    if Enum.all?(Map.keys(parent.children), &MapSet.member?(from, &1)) do
      {loads, to} = Aim.board(parent.spec.layout, work, parent.traced_by, Child.job_time(parent))
      parent = %{parent | strategy_state: %{board | board: true}}

      to
      |> Enum.filter(&is_map_key(parent.children, &1))
      |> Enum.reduce(parent, fn i, p ->
        Parent.send_counted(p, Map.fetch!(p.children, i), :control, {:loads, loads})
      end)
    else
      parent
    end
  end

  defp board(parent), do: parent

  @impl true
  def idle(child), do: idle(child, child.spec.aim)

  # `aim?` false: the offer goes to the left sibling, as after a miss.
  defp idle(child, aim?) do
    seq = seq(child) + 1

    rate = Child.rate(child)
    {heard, child} = hear(child, rate, [])
    {known, child} = learn_loads(child, [])
    target = if aim?, do: aim(child, known)

    {to, to_index} =
      if target,
        do: {Child.sibling(child, target), target},
        else: {child.left, child.left_index}

    offer =
      %HelpOffer{
        origin: child.index,
        pid: self(),
        seq: seq,
        via: self(),
        rate: rate,
        atom_us: Child.mean_atom_us(child),
        heard: heard,
        loads: Aim.news(known),
        aimed: target,
        home_left: if(target, do: {child.left, child.left_index})
      }
      |> HelpOffer.hop(child.index, to_index)

    # Offers held while we traced our last atom leave with ours, in one
    # message, to our left sibling (ours may be aimed elsewhere).
    {held, child} = take_offers(child, :held)

    held =
      Enum.map(
        held,
        &HelpOffer.hop(
          %{&1 | via: self(), heard: heard, loads: Aim.news(known)},
          child.index,
          child.left_index
        )
      )

    {with_ours, to_left} = if target, do: {[], held}, else: {held, []}

    child
    |> send_offers(to, [offer | with_ours])
    |> send_offers(child.left, to_left)
    |> Child.event(:offer, to_index)
    |> then(&Enum.reduce(held, &1, fn _, c -> Child.event(c, :pass, child.left_index) end))
    |> Child.bump(:offers_sent)
    |> put_strategy(seq: seq, current: seq, sent_to: to_index)
    |> Map.put(:status, :offered)
  end

  defp send_offers(child, _to, []), do: child

  defp send_offers(child, to, offers),
    do: Child.send_counted(child, to, :offer, offers_message(offers))

  @impl true
  def handle_message({:help_offer, %HelpOffer{} = offer}, child),
    do: {:ok, child |> offer(offer) |> flush()}

  def handle_message({:help_offers, offers}, child) when is_list(offers),
    do: {:ok, offers |> Enum.reduce(child, &offer(&2, &1)) |> flush()}

  def handle_message({:handover, from, atoms, loads}, child) when is_list(atoms) do
    {_, child} = learn_loads(child, loads)
    handle_message({:handover, from, atoms}, child)
  end

  def handle_message({:handover, from, atoms}, child) when is_list(atoms) do
    # Atoms again: the offers parked while we were idle (or held while we
    # traced our last atom) get the share rule.
    {parked, child} = take_offers(child, :parked)
    {held, child} = take_offers(child, :held)
    child = Child.receive_atoms(child, atoms)
    {:ok, (parked ++ held) |> Enum.reduce(child, &offer(&2, &1, from)) |> flush()}
  end

  def handle_message({:loads, loads}, child) when is_list(loads),
    do: {:ok, child |> learn_loads(loads) |> elem(1)}

  def handle_message({:ring_skip, gone, left, left_index}, child) do
    if child.left == gone and left_index not in child.dead do
      {:ok, %{child | left: left, left_index: left_index}}
    else
      {:ok, child}
    end
  end

  def handle_message(_msg, _child), do: :unhandled

  # An offer whose origin has died goes no further (see HelpOffer, "Strays").
  defp offer(child, offer, released_by \\ nil) do
    if offer.origin in child.dead, do: child, else: answer(child, offer, released_by)
  end

  defp answer(child, offer, released_by) do
    {remaining, in_flight} = Child.giveable(child)

    # What the offer heard goes into what we know; what we know goes on with
    # the offer.
    rate = Child.rate(child)
    {heard, child} = hear(child, rate, offer.heard)
    {known, child} = learn_loads(child, offer.loads)
    offer = %{offer | heard: heard, loads: Aim.news(known)}

    view = %{
      index: child.index,
      remaining: remaining,
      in_flight: in_flight,
      rate: rate,
      heard: heard,
      ring_size: child.ring_size - length(child.dead),
      offer_seq: if(child.status == :offered, do: child.strategy_state[:current]),
      remaining_us: if(in_flight > 0, do: Child.expected_remaining_us(child)),
      hold_after: child.spec.hold_after
    }

    case HelpOffer.decide(view, offer) do
      :returned when offer.aimed != nil ->
        # Our aimed offer missed and its target could not send it on to our
        # left sibling (dead, as far as it knew): walk the ring from here.
        idle(child, false)

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

      {:give, g} ->
        {atoms, child} = Child.take_last(child, g)

        child
        |> hand_over(offer.pid, offer.origin, atoms)
        |> Child.event(:give, offer.origin)
        |> Child.bump(:offers_consumed)

      _ when offer.aimed == child.index ->
        # Aimed here and nothing to give (a miss): the offer walks the ring
        # from its origin's left sibling, as if its origin had sent it there,
        # with our own load first among those it carries.
        miss(child, %{offer | loads: Aim.news(known, own_load(child))})

      :park ->
        keep(child, :parked, offer)

      :home ->
        child
        |> Child.send_counted(offer.pid, :offer, {:help_offer, offer})
        |> Child.event(:back, offer.origin)
        |> Child.bump(:offers_passed)

      :hold ->
        keep(child, :held, %{offer | held: true})

      :pass ->
        child = if child.status == :finished, do: splice(child, offer), else: child

        {to, to_index} =
          if is_integer(released_by) and released_by != child.index and
               released_by not in child.dead,
             do: {Child.sibling(child, released_by), released_by},
             else: {child.left, child.left_index}

        child
        |> keep(:outbox, {to, HelpOffer.hop(%{offer | via: self()}, child.index, to_index)})
        |> Child.event(:pass, to_index)
    end
  end

  defp miss(child, %HelpOffer{home_left: {left, left_index}} = offer) do
    if left_index in child.dead do
      child
      |> Child.send_counted(offer.pid, :offer, {:help_offer, offer})
      |> Child.event(:back, offer.origin)
      |> Child.bump(:offers_passed)
    else
      walking =
        %{offer | aimed: nil, home_left: nil, wrapped: false, hops: 0, via: offer.pid}
        |> HelpOffer.hop(offer.origin, left_index)

      child
      |> Child.send_counted(left, :offer, {:help_offer, walking})
      |> Child.event(:pass, left_index)
      |> Child.bump(:offers_passed)
    end
  end

  # Atoms to an offerer; where children aim, with our own load (just
  # lowered) and the latest-ending ones we know of.
  defp hand_over(%{spec: %{aim: true}} = child, pid, to, atoms) do
    {known, child} = learn_loads(child, [])
    Child.hand_over(child, pid, to, atoms, Aim.news(known, own_load(child)))
  end

  defp hand_over(child, pid, to, atoms), do: Child.hand_over(child, pid, to, atoms)

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

  # What a child knows of its siblings' loads, with `news` and its own load
  # added; kept, and returned. Without aiming, nothing.
  defp learn_loads(%{spec: %{aim: true}} = child, news) do
    known = Aim.learn(child.strategy_state[:loads] || [], [own_load(child) | news])
    {known, put_strategy(child, loads: known)}
  end

  defp learn_loads(child, _news), do: {[], child}

  # When this child expects to have traced all it holds (job microseconds),
  # and how many atoms it holds queued.
  defp own_load(child) do
    now = Child.job_time(child)
    {remaining, in_flight} = Child.giveable(child)
    mean = Child.mean_atom_us(child) || 0
    current = if in_flight > 0, do: Child.expected_remaining_us(child) || 0, else: 0
    {child.index, now + remaining * mean + current, now, remaining}
  end

  defp aim(child, known) do
    Aim.target(known, %{
      index: child.index,
      left_index: child.left_index,
      dead: child.dead,
      now: Child.job_time(child),
      min_us: Child.mean_atom_us(child) || 0
    })
  end

  defp put_strategy(child, kv),
    do: %{child | strategy_state: Map.merge(child.strategy_state, Map.new(kv))}
end
