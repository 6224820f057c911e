defmodule RingTracer.Strategy.Ring do
  @moduledoc false
  # The paper's ring: an idle child sends a help offer to its left sibling; a
  # sibling with atoms to spare consumes it and hands a share sized to the
  # children's speeds directly to the offerer, or passes it on; a child whose
  # own offer comes back is finished. The rules are `RingTracer.Strategy.Ring.HelpOffer`
  # and `RingTracer.Strategy.Ring.Share`; so are our additions: speeds measured in
  # kernel work per busy microsecond, a share planned with one more helper
  # than the two children (gossip: offers carry the fastest siblings heard
  # of), parking (an idle child keeps the offers that reach it until its own
  # offer is answered), holding (in a large ring, an offer that walked far
  # waits for a child about to run out and leaves with that child's own
  # offer, in one message), splicing (offers stop visiting finished
  # children, once a job has no frames left to come) and aiming (on strips, an idle child's offer goes straight to
  # the sibling it expects to stay busy longest: `RingTracer.Strategy.Ring.Aim`).
  #
  # ## Options
  #
  # Checked and completed by `options/2` (`RingTracer.Strategy.Ring.Options`):
  # `:hold_after`, `:aim`, `:split`, `:part_us`, `:part_rows`, `:cut_faster`.
  #
  # ## State
  #
  # A child's: its offers' sequence numbers (`:seq`, `:current`) and where
  # its current offer went (`:sent_to`), the offers it keeps (`:parked`,
  # `:held`) or is about to pass on (`:outbox`), what it has heard of the
  # fastest siblings (`:heard`) and of their loads (`:loads`). The parent's:
  # the board (`RingTracer.Strategy.Ring.Aim.board/4`) it makes once.

  use RingTracer.Strategy

  alias RingTracer.Strategy.Ring.{Aim, HelpOffer, State}
  alias RingTracer.Strategy.Ring.Options, as: RingOptions
  alias RingTracer.Strategy.View

  # Offers in a list leave one at a time (each may give atoms, and the next
  # one sees what is left), then together (`flush/1`).
  @answer {__MODULE__, :answer}

  # Adaptive atoms: at most this many parts per atom; before a child's
  # first atom is back, this many.
  @max_parts 8
  @first_parts 4

  @impl true
  def options(options, layout), do: RingOptions.validate(options, layout)

  @impl true
  def init(_options), do: %State{}

  ## The parent's side of aiming: a preview of each atom's work, traced beside
  ## the children's first atoms where the kernel can make one, then one board
  ## (`RingTracer.Strategy.Ring.Aim.board/4`) once every child has sent an atom.

  @impl true
  def parent_start(view, options) do
    # The board is one image's (each atom's work, from a preview of it): a
    # job of several frames goes without, its children aim by what they
    # hear from each other.
    if Keyword.fetch!(options, :aim) and view.spec.layout.frames == 1 do
      %{spec: %{kernel: {kernel, opts}} = spec} = view
      {:module, _} = Code.ensure_loaded(kernel)

      effects =
        if function_exported?(kernel, :atom_work, 2),
          do: [{:helper, {:atom_work, spec.id}, {kernel, :atom_work, [spec, opts]}}],
          else: []

      {%{work: nil, heard_from: MapSet.new(), board: false}, effects}
    else
      {nil, []}
    end
  end

  @impl true
  def parent_atom_done(view, %{board: false} = board, index),
    do: board(view, %{board | heard_from: MapSet.put(board.heard_from, index)})

  def parent_atom_done(_view, state, _index), do: {state, []}

  @impl true
  def parent_info({{:atom_work, id}, result}, view, %{board: false} = board)
      when id == view.spec.id do
    case result do
      {:ok, work} -> board(view, %{board | work: work})
      # No preview: no board; offers still carry the loads children report.
      {:error, _} -> {%{board | board: true}, []}
    end
  end

  def parent_info(_message, _view, state), do: {state, []}

  defp board(view, %{work: work, heard_from: from} = board) when work != nil do
    # The children the layout has strips for: one that joined later
    # (`RingTracer.grow/4`) may never trace an atom.
    first = for i <- Map.keys(view.children), i < view.spec.layout.children, do: i

    if Enum.all?(first, &MapSet.member?(from, &1)) do
      {loads, to} = Aim.board(view.spec.layout, work, view.traced_by, view.now)

      effects =
        for i <- to, is_map_key(view.children, i), do: {:send, i, :control, {:loads, loads}}

      {%{board | board: true}, effects}
    else
      {board, []}
    end
  end

  defp board(_view, board), do: {board, []}

  ## A child's side

  # With adaptive atoms, a child slower than a sibling it has heard of
  # traces its atoms in parts, so that the last one can be cut for a faster
  # sibling (`RingTracer.Strategy.Ring.HelpOffer`, `{:cut, keep}`): no more
  # parts than that sibling is faster, none shorter than `:part_us` (each
  # part is a kernel call) or than `:part_rows` rows (the kernel traces
  # primary rays in tiles of 4 x 4 pixels); a power of two, at most 8.
  # Before its first atom is back a child knows nothing of its speed, and
  # the two atoms it starts with are the ones most likely to end late on a
  # slow machine: those go in 4 parts.
  @impl true
  def parts(view, state) do
    part_rows = max(Keyword.fetch!(view.options, :part_rows), 1.0e-9)

    cond do
      not split?(view) ->
        1

      view.mean_atom_us == nil ->
        power_of_two(min(@first_parts, view.next_rows / part_rows))

      true ->
        part_us = max(Keyword.fetch!(view.options, :part_us), 1)
        faster = faster(view, state.heard)
        power_of_two(Enum.min([faster, view.mean_atom_us / part_us, view.next_rows / part_rows]))
    end
  end

  defp power_of_two(n) when n >= 2, do: min(2 ** floor(:math.log2(n)), @max_parts)
  defp power_of_two(_n), do: 1

  # How many times faster than this child the fastest it has heard of is
  # (0 before it has heard of anyone).
  defp faster(view, heard) do
    case {view.rate, Enum.reject(heard, &(elem(&1, 1) == view.index))} do
      {mine, [{fastest, _, _} | _]} when is_number(mine) and mine > 0 -> fastest / mine
      _ -> 0
    end
  end

  @impl true
  def idle(view, state), do: idle(view, state, aim?(view))

  # `aim?` false: the offer goes to the left sibling, as after a miss.
  defp idle(view, state, aim?) do
    seq = state.seq + 1
    {heard, state} = hear(view, state, [])
    {known, state} = learn_loads(view, state, [])
    target = if aim?, do: aim(view, known)

    {to, to_index} =
      if target, do: {{:sibling, target}, target}, else: {view.left, view.left_index}

    offer =
      %HelpOffer{
        origin: view.index,
        pid: view.pid,
        seq: seq,
        via: view.pid,
        rate: view.rate,
        atom_us: view.mean_atom_us,
        heard: heard,
        loads: Aim.news(known),
        aimed: target,
        home_left: if(target, do: {view.left, view.left_index})
      }
      |> HelpOffer.hop(view.index, to_index)

    # Offers held while we traced our last atom leave with ours, in one
    # message, to our left sibling (ours may be aimed elsewhere).
    {held, state} = take_offers(view, state, :held)

    held =
      Enum.map(
        held,
        &HelpOffer.hop(
          %{&1 | via: view.pid, heard: heard, loads: Aim.news(known)},
          view.index,
          view.left_index
        )
      )

    {with_ours, to_left} = if target, do: {[], held}, else: {held, []}

    effects =
      send_offers(to, [offer | with_ours]) ++
        send_offers(view.left, to_left) ++
        [{:event, :offer, to_index}] ++
        Enum.map(held, fn _ -> {:event, :pass, view.left_index} end) ++
        [{:stat, :offers_sent}]

    {%{state | seq: seq, current: seq, sent_to: to_index}, effects}
  end

  defp send_offers(_to, []), do: []
  defp send_offers(to, offers), do: [{:send, to, :offer, offers_message(offers)}]

  @impl true
  def handle_message({:help_offer, %HelpOffer{} = offer}, view, state),
    do: answer_all([offer], nil, view, state)

  def handle_message({:help_offers, offers}, view, state) when is_list(offers),
    do: answer_all(offers, nil, view, state)

  def handle_message({@answer, offers, released_by}, view, state),
    do: answer_all(offers, released_by, view, state)

  def handle_message({:handover, from, atoms, loads}, view, state) when is_list(atoms) do
    {_, state} = learn_loads(view, state, loads)
    handle_message({:handover, from, atoms}, view, state)
  end

  def handle_message({:handover, from, atoms}, view, state) when is_list(atoms) do
    # Atoms again: the offers parked while we were idle (or held while we
    # traced our last atom) get the share rule, once the atoms are queued.
    {parked, state} = take_offers(view, state, :parked)
    {held, state} = take_offers(view, state, :held)
    {state, [{:queue, atoms}, {:continue, {@answer, parked ++ held, from}}]}
  end

  def handle_message({:loads, loads}, view, state) when is_list(loads),
    do: {view |> learn_loads(state, loads) |> elem(1), []}

  def handle_message({:ring_skip, gone, left, left_index}, view, state) do
    if view.left == gone and left_index not in view.dead,
      do: {state, [{:left, left, left_index}]},
      else: {state, []}
  end

  # Our offer went to a sibling that died: send a fresh one. (One passed on
  # to it later is lost too, but sending afresh whenever that may be doubled
  # every idle child's offers after each failure; the job ends anyway, since
  # the parent hands the dead child's atoms out again itself.)
  def handle_message({:siblings_died, dead}, %View{status: :idle} = view, state) do
    if (state.sent_to || hd(dead)) in dead, do: idle(view, state), else: {state, []}
  end

  def handle_message(_message, _view, state), do: {state, []}

  # Where children aim, a hand-over carries the giver's own load (just
  # lowered) and the latest-ending ones it knows of.
  @impl true
  def handover_news(view, state) do
    if aim?(view) do
      {known, state} = learn_loads(view, state, [])
      {Aim.news(known, own_load(view)), state}
    else
      {nil, state}
    end
  end

  # One offer at a time; once the last is answered, the offers passed on
  # leave together.
  defp answer_all([], _released_by, _view, state), do: flush(state)

  defp answer_all([offer | rest], released_by, view, state) do
    {state, effects} = offer(view, state, offer, released_by)

    if rest == [] do
      {state, flushed} = flush(state)
      {state, effects ++ flushed}
    else
      {state, effects ++ [{:continue, {@answer, rest, released_by}}]}
    end
  end

  # An offer whose origin has died goes no further (see HelpOffer, "Strays").
  defp offer(view, state, offer, released_by) do
    if offer.origin in view.dead, do: {state, []}, else: answer(view, state, offer, released_by)
  end

  defp answer(view, state, offer, released_by) do
    # What the offer heard goes into what we know; what we know goes on with
    # the offer.
    {heard, state} = hear(view, state, offer.heard)
    {known, state} = learn_loads(view, state, offer.loads)
    offer = %{offer | heard: heard, loads: Aim.news(known)}
    decision = HelpOffer.decide(decision_view(view, state, heard), offer)
    act(decision, offer, view, state, {known, released_by})
  end

  # What `HelpOffer.decide/2` weighs, from the view and what we know.
  defp decision_view(view, state, heard) do
    %{
      index: view.index,
      remaining: view.remaining,
      in_flight: view.in_flight,
      rate: view.rate,
      heard: heard,
      ring_size: view.ring_size - length(view.dead),
      offer_seq: if(view.status == :idle, do: state.current),
      remaining_us: if(view.in_flight > 0, do: view.remaining_us),
      hold_after: Keyword.fetch!(view.options, :hold_after),
      split: split?(view),
      last_share: view.last_share,
      cuttable: view.cuttable,
      cut_faster: Keyword.fetch!(view.options, :cut_faster)
    }
  end

  # A decision carried out: `{known, released_by}` are the loads we know and
  # the sibling whose hand-over released the offer, if any.
  defp act(:returned, %HelpOffer{aimed: aimed}, view, state, _) when aimed != nil,
    # Our aimed offer missed and its target could not send it on to our left
    # sibling (dead, as far as it knew): walk the ring from here.
    do: idle(view, state, false)

  defp act(:returned, _offer, view, state, _) do
    {parked, state} = take_offers(view, state, :parked)

    # Every sibling was asked after these offers were made: their origins
    # are finished too.
    {state, [{:event, :returned, view.index}, :finished | Enum.flat_map(parked, &home/1)]}
  end

  defp act(:drop, _offer, _view, state, _), do: {state, []}

  defp act({:give, g}, offer, _view, state, _),
    do: {state, consume({:give, offer.pid, offer.origin, g}, offer)}

  defp act({:cut, keep}, offer, _view, state, _),
    do: {state, consume({:cut, offer.pid, offer.origin, keep}, offer)}

  defp act({:give, g, part}, offer, _view, state, _),
    do: {state, consume({:give, offer.pid, offer.origin, g, part}, offer)}

  # Aimed here and nothing to give (a miss): the offer walks the ring from
  # its origin's left sibling, as if its origin had sent it there, with our
  # own load first among those it carries.
  defp act(_decision, %HelpOffer{aimed: index} = offer, %View{index: index} = view, state, ctx) do
    {known, _released_by} = ctx
    {state, miss(view, %{offer | loads: Aim.news(known, own_load(view))})}
  end

  defp act(:park, offer, _view, state, _), do: {keep(state, :parked, offer), []}
  defp act(:home, offer, _view, state, _), do: {state, home(offer)}
  defp act(:hold, offer, _view, state, _), do: {keep(state, :held, %{offer | held: true}), []}

  defp act(:pass, offer, view, state, {_known, released_by}) do
    {to, to_index} =
      if is_integer(released_by) and released_by != view.index and
           released_by not in view.dead,
         do: {{:sibling, released_by}, released_by},
         else: {view.left, view.left_index}

    passed = HelpOffer.hop(%{offer | via: view.pid}, view.index, to_index)

    {keep(state, :outbox, {to, to_index, passed}),
     splice(view, offer) ++ [{:event, :pass, to_index}]}
  end

  # An offer consumed: what we give, as the event and counter say.
  defp consume(give, offer), do: [give, {:event, :give, offer.origin}, {:stat, :offers_consumed}]

  # An offer sent back to its origin.
  defp home(offer) do
    [
      {:send, offer.pid, :offer, {:help_offer, offer}},
      {:event, :back, offer.origin},
      {:stat, :offers_passed}
    ]
  end

  defp miss(view, %HelpOffer{home_left: {left, left_index}} = offer) do
    if left_index in view.dead do
      home(offer)
    else
      walking =
        %{offer | aimed: nil, home_left: nil, wrapped: false, hops: 0, via: offer.pid}
        |> HelpOffer.hop(offer.origin, left_index)

      [
        {:send, left, :offer, {:help_offer, walking}},
        {:event, :pass, left_index},
        {:stat, :offers_passed}
      ]
    end
  end

  # A finished child asks whoever sent it an offer to skip it from now on.
  defp splice(%View{status: :finished, more_frames: false} = view, %HelpOffer{via: via})
       when is_pid(via) and via != view.pid,
       do: [{:send, via, :control, {:ring_skip, view.pid, view.left, view.left_index}}]

  defp splice(_view, _offer), do: []

  defp keep(state, key, item), do: Map.update!(state, key, &(&1 ++ [item]))

  # One offer travels alone, several in one message.
  defp offers_message([offer]), do: {:help_offer, offer}
  defp offers_message(offers), do: {:help_offers, offers}

  # Parked or held offers, less those whose origin has died since.
  defp take_offers(view, state, key) do
    offers = Map.fetch!(state, key)
    {Enum.reject(offers, &(&1.origin in view.dead)), Map.put(state, key, [])}
  end

  # Offers passed on while handling one message leave together: one message
  # per sibling they go to.
  defp flush(state) do
    {outbox, state} = {state.outbox, %{state | outbox: []}}

    effects =
      outbox
      |> Enum.group_by(&elem(&1, 1))
      |> Enum.flat_map(fn {_index, [{to, _, _} | _] = group} ->
        [
          {:send, to, :offer, offers_message(Enum.map(group, &elem(&1, 2)))},
          {:stat, :offers_passed}
        ]
      end)

    {state, effects}
  end

  # What a child has heard of the fastest siblings, with `news` and its own
  # newest rate added and dead siblings left out; kept, and returned.
  defp hear(view, state, news) do
    mine = {view.rate, view.index, view.done}
    known = state.heard

    dead? = fn {_, i, _} -> i in view.dead end
    heard = HelpOffer.learn(Enum.reject(known, dead?), Enum.reject([mine | news], dead?))

    {heard, %{state | heard: heard}}
  end

  # What a child knows of its siblings' loads, with `news` and its own load
  # added; kept, and returned. Without aiming, nothing.
  defp learn_loads(view, state, news) do
    if aim?(view) do
      known = Aim.learn(state.loads, [own_load(view) | news])
      {known, %{state | loads: known}}
    else
      {[], state}
    end
  end

  # When this child expects to have traced all it holds (job microseconds),
  # and how many atoms it holds queued.
  defp own_load(view) do
    mean = view.mean_atom_us || 0
    current = if view.in_flight > 0, do: view.remaining_us || 0, else: 0
    {view.index, view.now + view.remaining * mean + current, view.now, view.remaining}
  end

  defp aim(view, known) do
    Aim.target(known, %{
      index: view.index,
      left_index: view.left_index,
      dead: view.dead,
      now: view.now,
      min_us: view.mean_atom_us || 0
    })
  end

  defp aim?(view), do: Keyword.fetch!(view.options, :aim)

  defp split?(view), do: Keyword.fetch!(view.options, :split)
end
