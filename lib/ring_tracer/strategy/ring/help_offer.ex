defmodule RingTracer.Strategy.Ring.HelpOffer do
  @moduledoc false
  # The help offer (the ring's token) and what a child does when one reaches it.
  #
  # A child that has traced every atom it holds sends an offer to its left
  # sibling: who made it (`origin`, `pid`), its speed (`rate`, kernel work
  # per busy microsecond, see `RingTracer.Strategy.Ring.Share`; `nil` until it has
  # traced work), its mean wall time per atom (`atom_us`, `nil` before its
  # first atom), the fastest siblings heard of along its way (`heard`, see
  # "Gossip") and a sequence number (`seq`) so that a child can tell its
  # current offer from a stale one; `wrapped` is set once the offer has gone
  # past the end of the ring (from a child to one with a higher index, see
  # "Parking"), `hops` counts the siblings it has been sent to and `held`
  # whether it has waited once (see "Holding"). Only the origin's own offers
  # carry its pid: atoms are handed over directly to it, not along the ring.
  # `via` is the last child that sent the offer on (see "Splicing" below).
  # `aimed` is the sibling an offer was sent straight to, if not its child's
  # left one, `home_left` that child's left sibling (`{pid, index}`) for the
  # walk a miss turns it into, and `loads` the siblings' loads it carries
  # (all three `RingTracer.Strategy.Ring.Aim`).
  #
  # `decide/2` is the whole rule, pure:
  #
  #   * the offer is the child's own and current -> `:returned`: nobody needed
  #     help, the child is finished and waits for the parent's stop message;
  #   * an old offer of its own (superseded) -> `:drop`;
  #   * the share rule gives at least one atom -> `{:give, g}`: the token is
  #     consumed, and the child sends its last `g` queued atoms to the offerer;
  #     with adaptive atoms (`split: true` in the view), `{:give, g, {k, 8}}`:
  #     `k` eighths of the next one too, near the end of the giver's atoms or
  #     (`g` 0) to an offerer too slow for a whole atom
  #     (`RingTracer.Strategy.Ring.Share.part/7`);
  #   * with adaptive atoms, nothing queued to give, and the atom being traced
  #     in parts with parts not yet started (`cuttable` in the view), to an
  #     offerer at least 1.5x faster -> `{:cut, keep}`: the child cuts that
  #     atom, keeps the `keep` share of its parts not started (both then end
  #     together, `keep` = giver's rate / both rates) and hands the rest over
  #     (`RingTracer.Job.Pipe.cut/3`): a fast child does not wait for a slow
  #     one's last atom;
  #   * the child is idle itself, its own offer still out, and the offer has
  #     not wrapped -> `:park`;
  #   * the child is tracing its last atom, which should end within half of
  #     one of the offerer's atoms, and the offer has walked `hold_after` hops
  #     without finding work -> `:hold`;
  #   * the offer has walked as many hops as the ring has live children
  #     without reaching its origin -> `:home` (see "Strays");
  #   * otherwise -> `:pass` to the left sibling.
  #
  # ## Gossip (our addition to the paper)
  #
  # The share rule plans for one more helper than the giver and the offerer:
  # the fastest sibling the giver has heard of. Every offer carries the three
  # fastest siblings heard of on its way, each as `{rate, index, done}` (what
  # it had `done`, atoms computed, when it told its rate: the newest report
  # of a sibling wins). Its origin puts itself in; a child adds what each
  # offer that reaches it carries to what it knows, and the offers it sends
  # or passes on carry the result. Until it has heard of anyone else, a giver
  # in a ring of three or more assumes a helper as fast as the faster of
  # itself and the offerer.
  #
  # More than one offer can be in the ring at once (one per idle child); they
  # cross freely.
  #
  # ## Parking (our addition to the paper)
  #
  # An idle child whose own offer is out has nothing to give, and its own offer
  # is ahead of the one that just reached it, asking the same siblings the same
  # question. So it keeps the newcomer instead of passing it on: when its own
  # offer is consumed it has atoms again and applies the share rule to what it
  # parked (give, or send the offer on to the sibling that just gave: the ones
  # in between had nothing a moment ago, and the giver may have more); when
  # its own offer comes back it is finished,
  # and it sends each parked offer back to its origin, which is then finished
  # too (the parker's offer visited every sibling after the parked offer was
  # made). Without parking, every child's last offer travels the whole ring:
  # N² messages at the end of a job, which with 1024 children is more than the
  # atoms themselves.
  #
  # "Finished too" is an approximation when the parked offer's origin is
  # faster than its parker: the share rule gives a faster offerer more, so a
  # sibling that had nothing for the parker might have had an atom for it.
  # Sending such offers on instead of home took 3,000-4,800 offer messages in
  # a job of 256 children x 8 atoms against 2,300-2,900 (both measured before
  # holding), for no balance gain we could measure, so they go home.
  #
  # A wrapped offer is never parked. Two idle children could otherwise each
  # hold the other's offer and both wait, idle, to the end of the job (we saw
  # the fastest of 8 children stranded so for the last tenth of a render). A
  # cycle of parked offers needs an offer that went all the way round to a
  # child on its origin's right, so past the end of the ring; with wrapped
  # offers passed on, no cycle forms and some offer always walks on.
  #
  # ## Holding (our addition to the paper)
  #
  # Near the end of a large job most children are tracing their last atom and
  # have nothing to give; an offer walks past them one message at a time, and
  # every idle child's offer makes that walk. So an offer that has walked
  # `hold_after` hops (default 16) without finding work waits, once, at a
  # child tracing its last atom, if that atom should end within half of one of
  # the offerer's own atoms (the child's mean time per atom minus what the atom
  # has run, against the offerer's mean time per atom, `atom_us`). When the child
  # runs out it sends its own offer, and the offers it held travel with it, in
  # one message (`{:help_offers, [...]}`): several offers walk for the price
  # of one. A child never waits on a held offer, so holding makes no cycles.
  # In a ring of a few children an offer goes home long before it has walked
  # 16 hops, so there it does not wait.
  #
  # ## Strays (our addition to the paper)
  #
  # In a ring of L live children an offer is back at its origin after at most
  # L hops (fewer where finished children were spliced out or a giver took a
  # parked offer on). One that has walked L hops and is still elsewhere walks
  # a ring its origin is no longer on: after a failure the parent hands the
  # lost atoms to children that had finished, and that their siblings had
  # spliced out; such a child's next offer would circle the others until the
  # job ends (thousands of messages, or a child passing an offer to itself
  # when it is the last one left). So it goes straight home, where it counts
  # as returned: every live child it visited had nothing to give. An offer
  # whose origin has died is dropped by the first child that knows of the
  # death.
  #
  # ## Splicing (our addition to the paper)
  #
  # A finished child will never have atoms to give, so offers gain nothing by
  # visiting it. When one passes through it, it tells the sender (`via`) to
  # skip it: `{:ring_skip, me, my_left, my_left_index}`; a sender whose left is
  # still that child adopts the new left, and otherwise ignores the message.
  # The ring shrinks to the children that may still give; every offer still
  # visits each of them.

  alias RingTracer.Strategy.Ring.Share

  @enforce_keys [:origin, :pid, :seq]
  defstruct [
    :origin,
    :pid,
    :seq,
    :via,
    :rate,
    :atom_us,
    heard: [],
    wrapped: false,
    aimed: nil,
    home_left: nil,
    loads: [],
    hops: 0,
    held: false
  ]

  @heard_max 3

  @hold_after 16

  # How much faster than the giver an offerer must be to get parts of the
  # atom being traced (a cut costs a message and a kernel call).
  @cut_faster 1.5

  @doc "Hops an offer walks before it may wait at a child (the `:hold_after` default)."
  @spec default_hold_after() :: pos_integer()
  def default_hold_after, do: @hold_after

  @doc "How much faster an offerer must be to cut the atom being traced (the `:cut_faster` default)."
  @spec default_cut_faster() :: float()
  def default_cut_faster, do: @cut_faster

  @type t :: %__MODULE__{
          origin: non_neg_integer(),
          pid: pid(),
          seq: non_neg_integer(),
          via: pid() | nil,
          rate: Share.rate(),
          atom_us: non_neg_integer() | nil,
          heard: heard(),
          wrapped: boolean(),
          aimed: non_neg_integer() | nil,
          home_left: {pid(), non_neg_integer()} | nil,
          loads: [RingTracer.Strategy.Ring.Aim.load()],
          hops: non_neg_integer(),
          held: boolean()
        }

  @typedoc "The fastest siblings heard of, fastest first: `{rate, index, done}`."
  @type heard :: [{float(), non_neg_integer(), non_neg_integer()}]

  @typedoc """
  What a child knows of itself when an offer arrives: its index, queued
  atoms it could give (`remaining`), atoms in its pipe (`in_flight`), its
  `rate`, its current offer's `seq` if it has one out. `heard` (the fastest
  live siblings it has heard of, the arriving offer's news included) and
  `ring_size` (live children) pick the share rule's third helper;
  `remaining_us` (how long its atom in flight should still take) and
  `hold_after` only matter for holding.
  """
  @type view :: %{
          required(:index) => non_neg_integer(),
          required(:remaining) => non_neg_integer(),
          required(:in_flight) => non_neg_integer(),
          required(:rate) => Share.rate(),
          required(:offer_seq) => non_neg_integer() | nil,
          optional(:heard) => heard(),
          optional(:ring_size) => non_neg_integer(),
          optional(:remaining_us) => non_neg_integer() | nil,
          optional(:hold_after) => pos_integer(),
          optional(:split) => boolean(),
          optional(:last_share) => float() | nil,
          optional(:cuttable) => non_neg_integer(),
          optional(:cut_faster) => float()
        }

  @type decision ::
          :returned
          | :drop
          | :park
          | :hold
          | :home
          | :pass
          | {:give, pos_integer()}
          | {:give, non_neg_integer(), {pos_integer(), 8}}
          | {:cut, float()}

  @doc """
  What the child described by `view` does with `offer`.

      iex> offer = %RingTracer.Strategy.Ring.HelpOffer{origin: 1, pid: self(), rate: 2.0, seq: 3}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 1, remaining: 0, in_flight: 0, rate: 2.0, offer_seq: 3}, offer)
      :returned
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 6, in_flight: 2, rate: 2.0, offer_seq: nil}, offer)
      {:give, 4}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 6, in_flight: 2, rate: 2.0, offer_seq: nil, heard: [{9.0, 5, 12}]}, offer)
      {:give, 1}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 1, rate: 2.0, offer_seq: nil}, offer)
      :pass
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 0, rate: 2.0, offer_seq: 5}, offer)
      :park
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 0, rate: 2.0, offer_seq: 5}, %{offer | wrapped: true})
      :pass
      iex> far = %{offer | hops: 16, atom_us: 4_000}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 1, rate: 2.0, offer_seq: nil, remaining_us: 1_500}, far)
      :hold
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 1, rate: 2.0, offer_seq: nil, remaining_us: 9_000}, far)
      :pass
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{index: 0, remaining: 0, in_flight: 1, rate: 2.0, offer_seq: nil, ring_size: 16}, far)
      :home
      iex> slow = %{index: 0, remaining: 0, in_flight: 1, rate: 0.5, offer_seq: nil, split: true, cuttable: 5}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(slow, offer)
      {:cut, 0.2}
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{slow | rate: 1.6}, offer)
      :pass
      iex> RingTracer.Strategy.Ring.HelpOffer.decide(%{slow | rate: nil}, offer)
      {:cut, 0.0}
  """
  @spec decide(view(), t()) :: decision()
  def decide(%{index: me, offer_seq: current}, %__MODULE__{origin: me, seq: seq}) do
    if seq == current, do: :returned, else: :drop
  end

  def decide(view, %__MODULE__{rate: rate, wrapped: wrapped} = offer) do
    helper = helper_rate(view, offer)

    case Share.give(view.remaining, view.in_flight, rate, view.rate, helper) do
      0 ->
        case part(view, offer, helper, 0) || cut(view, offer) do
          nil when view.offer_seq != nil and not wrapped -> :park
          {:cut, _} = cut -> cut
          nil -> if holds?(view, offer), do: :hold, else: walk_on(view, offer)
          part -> {:give, 0, part}
        end

      g ->
        case part(view, offer, helper, g) do
          nil -> {:give, g}
          part -> {:give, g, part}
        end
    end
  end

  # Adaptive atoms (`Share.part/7`): part of one more atom, or none.
  defp part(%{split: true} = view, offer, helper, g) do
    Share.part(
      view.remaining,
      view.in_flight,
      offer.rate,
      view.rate,
      helper,
      g,
      view[:last_share]
    )
  end

  defp part(_view, _offer, _helper, _g), do: nil

  # Adaptive atoms: parts of the atom being traced, to a much faster offerer
  # (as for the share rule, one that has finished its atoms before the giver
  # finished its first is: it gets every part not started).
  defp cut(%{split: true, remaining: 0, rate: mine} = view, %__MODULE__{rate: theirs}) do
    cond do
      Map.get(view, :cuttable, 0) == 0 ->
        nil

      not is_number(theirs) ->
        nil

      mine == nil ->
        {:cut, 0.0}

      mine > 0 and theirs >= Map.get(view, :cut_faster, @cut_faster) * mine ->
        {:cut, mine / (mine + theirs)}

      true ->
        nil
    end
  end

  defp cut(_view, _offer), do: nil

  # An offer that has walked as many hops as the ring has live children
  # without reaching its origin goes home (see "Strays").
  defp walk_on(%{ring_size: live}, %__MODULE__{hops: hops}) when hops >= live, do: :home
  defp walk_on(_view, _offer), do: :pass

  # The share rule's third helper: the fastest sibling heard of other than
  # the two; none heard of, one as fast as the faster of the two if the ring
  # has a third child at all.
  defp helper_rate(view, offer) do
    others =
      for {rate, i, _} <- Map.get(view, :heard, []), i != view.index, i != offer.origin, do: rate

    case others do
      [rate | _] -> rate
      [] -> if Map.get(view, :ring_size, 0) >= 3, do: faster(offer.rate, view.rate)
    end
  end

  defp faster(a, b) when is_number(a) and is_number(b), do: max(a, b)
  defp faster(a, b), do: a || b

  @doc """
  What is known of the fastest siblings, `known`, with `news` added: one
  entry per sibling (its newest report: the highest `done`), the #{@heard_max}
  fastest, fastest first. Reports without a rate are ignored.

      iex> RingTracer.Strategy.Ring.HelpOffer.learn([{3.0, 1, 9}, {1.0, 2, 4}], [{2.0, 4, 3}, {5.0, 2, 6}, {4.0, 1, 2}])
      [{5.0, 2, 6}, {3.0, 1, 9}, {2.0, 4, 3}]
  """
  @spec learn(heard(), [{Share.rate(), non_neg_integer(), non_neg_integer()}]) :: heard()
  def learn(known, news) do
    (known ++ news)
    |> Enum.filter(fn {rate, _, _} -> is_number(rate) end)
    |> Enum.group_by(&elem(&1, 1))
    |> Enum.map(fn {_, reports} ->
      Enum.max_by(reports, fn {rate, _, done} -> {done, rate} end)
    end)
    |> Enum.sort(:desc)
    |> Enum.take(@heard_max)
  end

  # Tracing its last atom, which ends within half of one of the offerer's
  # atoms, and the offer has walked far and never waited.
  defp holds?(view, %__MODULE__{held: held, hops: hops, atom_us: atom_us}) do
    remaining_us = Map.get(view, :remaining_us)

    view.offer_seq == nil and view.remaining == 0 and view.in_flight > 0 and not held and
      hops >= Map.get(view, :hold_after, @hold_after) and is_integer(remaining_us) and
      is_integer(atom_us) and 2 * remaining_us <= atom_us
  end

  @doc """
  `offer` as sent on from child `from` to child `to`: one hop more, and
  marked `wrapped` if the hop goes past the end of the ring (to a higher
  index).

      iex> offer = %RingTracer.Strategy.Ring.HelpOffer{origin: 1, pid: self(), seq: 3}
      iex> RingTracer.Strategy.Ring.HelpOffer.hop(offer, 1, 0)
      %RingTracer.Strategy.Ring.HelpOffer{origin: 1, pid: self(), seq: 3, hops: 1, wrapped: false}
      iex> RingTracer.Strategy.Ring.HelpOffer.hop(offer, 0, 3).wrapped
      true
  """
  @spec hop(t(), non_neg_integer(), non_neg_integer()) :: t()
  def hop(%__MODULE__{} = offer, from, to),
    do: %{offer | wrapped: offer.wrapped or to > from, hops: offer.hops + 1}
end
