defmodule RingTracer.Strategy.Ring.HelpOfferTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Strategy.Ring.HelpOffer

  alias RingTracer.Strategy.Ring.HelpOffer

  defp offer(origin, rate, seq \\ 1),
    do: %HelpOffer{origin: origin, pid: self(), rate: rate, seq: seq}

  defp view(index, remaining, in_flight, rate, seq),
    do: %{index: index, remaining: remaining, in_flight: in_flight, rate: rate, offer_seq: seq}

  test "a child's own current offer coming back means it is finished" do
    assert HelpOffer.decide(view(2, 0, 0, 9.0, 4), offer(2, 9.0, 4)) == :returned
  end

  test "a stale offer of one's own is dropped" do
    assert HelpOffer.decide(view(2, 0, 0, 9.0, 5), offer(2, 9.0, 4)) == :drop
    assert HelpOffer.decide(view(2, 3, 1, 9.0, nil), offer(2, 9.0, 4)) == :drop
  end

  test "an idle child with its own offer out parks other children's offers" do
    assert HelpOffer.decide(view(1, 0, 0, 9.0, 3), offer(2, 9.0)) == :park
  end

  test "a child with nothing to spare and no offer out passes other children's offers on" do
    assert HelpOffer.decide(view(1, 0, 0, 9.0, nil), offer(2, 9.0)) == :pass
    assert HelpOffer.decide(view(1, 0, 2, 9.0, nil), offer(2, 9.0)) == :pass
  end

  test "a busy child consumes the offer and gives a share sized to the speeds" do
    # Three times faster: the giver keeps one atom (done at 3/4, behind its 2
    # in flight), the offerer gets 11 (done at 11/12).
    assert HelpOffer.decide(view(1, 12, 2, 4.0, nil), offer(2, 12.0)) == {:give, 11}
  end

  test "adaptive atoms: part of an atom near the end, or for an offerer too slow for a whole one" do
    split = fn v, share -> Map.merge(v, %{split: true, last_share: share}) end
    # An offerer at 0.4 of the giver's speed, one atom queued behind the one
    # in flight: a whole atom would end later on it, half of one does not.
    assert HelpOffer.decide(split.(view(1, 1, 1, 1.0, nil), 1.0), offer(2, 0.4)) ==
             {:give, 0, {4, 8}}

    # Without adaptive atoms the same offer walks on.
    assert HelpOffer.decide(view(1, 1, 1, 1.0, nil), offer(2, 0.4)) == :pass
    # An eighth-speed offerer, five atoms queued and one in flight, nobody
    # else to help: five eighths of one (it ends them as the giver ends the
    # rest).
    assert HelpOffer.decide(split.(view(1, 5, 1, 1.0, nil), 1.0), offer(2, 0.125)) ==
             {:give, 0, {5, 8}}

    # A piece of a quarter of an atom is not cut again.
    assert HelpOffer.decide(split.(view(1, 1, 1, 1.0, nil), 0.25), offer(2, 0.4)) == :pass
    # Far from the end, whole atoms only.
    assert HelpOffer.decide(split.(view(1, 12, 2, 4.0, nil), 1.0), offer(2, 12.0)) == {:give, 11}
  end

  test "the third helper is the fastest sibling heard of other than the two" do
    slow = offer(2, 1.0)
    base = view(1, 12, 1, 2.0, nil)
    # Only the two heard of: as in a ring of two.
    alone = HelpOffer.decide(base, slow)
    assert alone == {:give, 4}
    heard = Map.put(base, :heard, [{8.0, 1, 9}, {4.0, 2, 3}])
    assert HelpOffer.decide(heard, slow) == alone
    # A faster third sibling heard of keeps the slow offerer's share small.
    assert HelpOffer.decide(%{heard | heard: [{8.0, 3, 9}, {2.0, 1, 5}]}, slow) == {:give, 1}
    # None heard of, in a ring of three or more: a helper as fast as the giver.
    assert HelpOffer.decide(Map.put(base, :ring_size, 3), slow) == {:give, 2}
    assert HelpOffer.decide(Map.put(base, :ring_size, 2), slow) == alone
  end

  test "what is known of the fastest siblings: each one's newest report, three at most" do
    assert HelpOffer.learn([], [{nil, 4, 0}, {2.0, 1, 3}]) == [{2.0, 1, 3}]
    known = HelpOffer.learn([{2.0, 1, 3}], [{1.0, 1, 5}, {5.0, 2, 1}, {3.0, 3, 1}, {0.5, 4, 1}])
    assert known == [{5.0, 2, 1}, {3.0, 3, 1}, {1.0, 1, 5}]
    # An older report does not undo a newer one.
    assert HelpOffer.learn(known, [{9.0, 1, 4}]) == known
  end
end
