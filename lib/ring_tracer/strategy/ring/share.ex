defmodule RingTracer.Strategy.Ring.Share do
  @moduledoc false
  # The help-offer share rule: how many atoms a child gives to a sibling that
  # offered help.
  #
  # ## Speeds
  #
  # The paper has the giver compare the offerer's count of computed atoms with
  # its own. Atoms differ in cost, though (on the SPD `balls` scene by 6x from
  # the sky to the reflective spheres), so a slow child that happened to trace
  # cheap atoms passes for a fast one. We compare speeds measured as kernel work
  # units per busy microsecond (`RingTracer.Job.Stats.rate/1`): work units cost
  # the same on every machine, and time is what a machine spends on them.
  #
  # ## The plan
  #
  # The giver plans where each of its `remaining` queued atoms would be
  # finished first, among:
  #
  #   * itself, behind the `in_flight` atoms already in its grandchild's pipe;
  #   * the offerer, idle;
  #   * in a ring of three or more, one more helper (`helper_rate`): the
  #     fastest other sibling it has heard of (offers carry what they heard,
  #     see `RingTracer.Strategy.Ring.HelpOffer`).
  #
  # Atoms go one at a time to whoever would complete one more soonest
  # (`(n + 1) / rate`; the giver first on ties, then the offerer), which is
  # list scheduling on machines of different speeds: for atoms of one cost,
  # the earliest common finish. The offerer gets the atoms planned for it, and,
  # if it is faster than the giver, the helper's as well: they wait where they
  # would be traced sooner, and go on from there when the helper's own offer
  # comes. A slower offerer does not take the helper's atoms: an atom handed to
  # a slow child ends late, while one left queued is there for the next offer.
  #
  # Without the helper, the rule would split the atoms as if nobody else would
  # help either child. Near the end of a job everybody does, and the pairwise
  # split handed slow children expensive atoms that ended after all the others
  # (8 children of speeds 1..8 on two cores: makespan / ideal 1.17-1.20 with
  # the pairwise rule on atom counts, 1.13-1.14 with this one).
  #
  # No rate yet: a giver that has not finished an atom gives all it has queued
  # (its offerer, which finished its own work, is faster); an offerer with no
  # rate counts as fast as the giver. Atoms in flight are never given.

  @typedoc "Kernel work units per microsecond; `nil` until a child has traced work."
  @type rate :: float() | nil

  # The smallest piece adaptive atoms cut, in atoms.
  @least_part 0.25

  # Queues up to this long are planned atom by atom.
  @one_by_one 64

  @doc """
  Atoms to give out of `remaining` queued ones, with `in_flight` atoms in the
  giver's pipe, the offerer's and the giver's rates and, if known, one more
  helper's.

  Where the offerer and the giver are about as fast, the helper's atoms go
  with whichever is faster by a hair: the result jumps there (from the
  offerer's own atoms to those plus the helper's). Both places are as good,
  so nothing is lost but the symmetry.

    iex> RingTracer.Strategy.Ring.Share.give(20, 0, 1.0, 1.0)
    10
    iex> RingTracer.Strategy.Ring.Share.give(6, 2, 1.0, 1.0)
    4
    iex> RingTracer.Strategy.Ring.Share.give(20, 0, 1.0, 1.0, 1.0)
    7
    iex> RingTracer.Strategy.Ring.Share.give(20, 0, 2.0, 1.0, 1.0)
    15
    iex> RingTracer.Strategy.Ring.Share.give(3, 1, 0.2, 1.0, 4.0)
    0
    iex> RingTracer.Strategy.Ring.Share.give(5, 1, 1.0, nil)
    5
  """
  @spec give(non_neg_integer(), non_neg_integer(), rate(), rate(), rate()) :: non_neg_integer()
  def give(remaining, in_flight, offerer_rate, self_rate, helper_rate \\ nil)

  def give(0, in_flight, _offerer_rate, _self_rate, _helper_rate)
      when is_integer(in_flight) and in_flight >= 0,
      do: 0

  def give(remaining, in_flight, offerer_rate, self_rate, helper_rate)
      when is_integer(remaining) and remaining > 0 and is_integer(in_flight) and in_flight >= 0 do
    if positive?(self_rate) do
      offerer_rate = if positive?(offerer_rate), do: offerer_rate, else: self_rate
      helper_rate = if positive?(helper_rate), do: helper_rate

      {_kept, to_offerer, to_helper} =
        plan(remaining, {in_flight, self_rate}, offerer_rate, helper_rate)

      if offerer_rate > self_rate, do: to_offerer + to_helper, else: to_offerer
    else
      remaining
    end
  end

  # The plan: atom by atom to whoever completes one more soonest, `(n + 1) /
  # rate` (the giver first on ties, then the offerer). The atoms completed by
  # a time `t` are `floor(t * rate)` per child (less the giver's in flight),
  # so a long queue is placed in whole rounds: the latest `t` that does not
  # place more than `remaining` (bisection), then the few atoms left one by
  # one. A short queue goes one by one straight away.
  defp plan(remaining, {start, vg}, vo, vh) when remaining <= @one_by_one,
    do: one_by_one(remaining, {start, 0, 0}, vg, vo, vh)

  defp plan(remaining, {start, vg}, vo, vh) do
    rates = [vg, vo, vh || 0.0]

    placed = fn t ->
      Enum.map(Enum.zip(rates, [start, 0, 0]), fn {v, s} -> max(floor(t * v) - s, 0) end)
    end

    hi = (remaining + start + 1) / Enum.min(Enum.filter(rates, &(&1 > 0)))

    [g, o, h] =
      Enum.reduce(1..64, {0.0, hi}, fn _, {lo, hi} ->
        mid = (lo + hi) / 2
        if Enum.sum(placed.(mid)) <= remaining, do: {mid, hi}, else: {lo, mid}
      end)
      |> elem(0)
      |> then(placed)

    one_by_one(remaining - g - o - h, {g + start, o, h}, vg, vo, vh)
  end

  defp one_by_one(0, {g, o, h}, _vg, _vo, _vh), do: {g, o, h}

  defp one_by_one(left, {g, o, h}, vg, vo, vh) do
    tg = (g + 1) / vg
    to = (o + 1) / vo

    next =
      cond do
        tg <= to and (vh == nil or tg <= (h + 1) / vh) -> {g + 1, o, h}
        vh == nil or to <= (h + 1) / vh -> {g, o + 1, h}
        true -> {g, o, h + 1}
      end

    one_by_one(left - 1, next, vg, vo, vh)
  end

  @doc """
  Adaptive atoms, at a hand-over: after the `g` whole atoms `give/5` gave,
  the share of the next one the offerer should take as well, in eighths
  (`{k, 8}`, `nil`: none), from the same rates. The atoms are shared as if
  they could be cut anywhere (the offerer's part of the `remaining` and
  `in_flight` atoms in proportion to its speed, with the helper's if it is
  faster than the giver) and the whole atoms given are taken off. With whole
  atoms given, only near the end of the giver's atoms (one or two left after
  the hand-over: before, the atoms themselves are small enough); with none
  (the offerer is too slow for a whole atom), whenever its part is worth a
  quarter of an atom: a slow child then stays busy to the end of the job
  instead of idling with its capacity lost. `share` is the share of its atom of
  the one to cut (a piece: less than 1.0); neither part is smaller than a
  quarter of an atom (smaller pieces cost more messages than they save
  time).

      iex> RingTracer.Strategy.Ring.Share.part(2, 1, 8.0, 1.0, nil, 1, 1.0)
      {6, 8}
      iex> RingTracer.Strategy.Ring.Share.part(2, 1, 1.0, 1.0, nil, 1, 1.0)
      {4, 8}
      iex> RingTracer.Strategy.Ring.Share.part(2, 1, 1.0, 1.0, nil, 1, 0.5)
      {4, 8}
      iex> RingTracer.Strategy.Ring.Share.part(2, 1, 1.0, 1.0, nil, 1, 0.4)
      nil
      iex> RingTracer.Strategy.Ring.Share.part(20, 1, 1.0, 1.0, nil, 10, 1.0)
      nil
      iex> RingTracer.Strategy.Ring.Share.part(5, 1, 0.125, 1.0, 1.0, 0, 1.0)
      {2, 8}
  """
  @spec part(
          non_neg_integer(),
          non_neg_integer(),
          rate(),
          rate(),
          rate(),
          non_neg_integer(),
          float() | nil
        ) :: {pos_integer(), 8} | nil
  def part(remaining, in_flight, offerer_rate, self_rate, helper_rate, g, share)
      when remaining > g and (g == 0 or remaining - g <= 2) and is_float(share) and
             share >= 2 * @least_part do
    if positive?(offerer_rate) and positive?(self_rate) do
      vh = if positive?(helper_rate), do: helper_rate, else: 0.0
      total = remaining + in_flight
      mine = if offerer_rate > self_rate, do: offerer_rate + vh, else: offerer_rate
      k = floor((total * mine / (offerer_rate + self_rate + vh) - g) * 8)
      # Neither part below a quarter of an atom (in eighths of this one).
      least = ceil(8 * @least_part / share - 1.0e-9)
      k = min(k, 8 - least)
      if k >= least, do: {k, 8}
    end
  end

  def part(_remaining, _in_flight, _offerer_rate, _self_rate, _helper_rate, _g, _share),
    do: nil

  defp positive?(rate), do: is_number(rate) and rate > 0
end
