defmodule RingTracer.Ring.HelpOfferTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Ring.HelpOffer

  alias RingTracer.Ring.HelpOffer

  defp offer(origin, done, seq \\ 1),
    do: %HelpOffer{origin: origin, pid: self(), done: done, seq: seq}

  defp view(index, remaining, in_flight, done, seq),
    do: %{index: index, remaining: remaining, in_flight: in_flight, done: done, offer_seq: seq}

  test "a child's own current offer coming back means it is finished" do
    assert HelpOffer.decide(view(2, 0, 0, 9, 4), offer(2, 9, 4)) == :returned
  end

  test "a stale offer of one's own is dropped" do
    assert HelpOffer.decide(view(2, 0, 0, 9, 5), offer(2, 9, 4)) == :drop
    assert HelpOffer.decide(view(2, 3, 1, 9, nil), offer(2, 9, 4)) == :drop
  end

  test "an idle child with its own offer out parks other children's offers" do
    assert HelpOffer.decide(view(1, 0, 0, 9, 3), offer(2, 9)) == :park
  end

  test "a child with nothing to spare and no offer out passes other children's offers on" do
    assert HelpOffer.decide(view(1, 0, 0, 9, nil), offer(2, 9)) == :pass
    assert HelpOffer.decide(view(1, 0, 2, 9, nil), offer(2, 9)) == :pass
  end

  test "a busy child consumes the offer and gives a speed-proportional share" do
    assert HelpOffer.decide(view(1, 12, 2, 4, nil), offer(2, 12)) == {:give, 10}
  end

  test "the atoms given are the last ones queued" do
    assert HelpOffer.split_queue([5, 6, 7], 0) == {[5, 6, 7], []}
    assert HelpOffer.split_queue([5, 6, 7], 3) == {[], [5, 6, 7]}
  end
end
