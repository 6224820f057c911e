defmodule RingTracer.Strategy.Ring.ShareTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Strategy.Ring.Share

  alias RingTracer.Strategy.Ring.Share

  test "equal speeds, no third helper: what is left is split in half" do
    assert Share.give(20, 0, 1.0, 1.0) == 10
    assert Share.give(21, 1, 1.0, 1.0) == 11
  end

  test "a slower offerer gets fewer atoms than a faster one" do
    slow = Share.give(30, 2, 0.25, 1.0)
    fast = Share.give(30, 2, 4.0, 1.0)
    assert slow < fast
    # The plan: each atom to whoever completes it first. A child 4x slower
    # completes its 6th atom at 24, the giver its 24th queued one (behind 2
    # in flight) at 26.
    assert slow == 6
    # Four times faster: the giver keeps 4 (done at 6), the offerer 26 (6.5).
    assert fast == 26
  end

  test "nothing queued, nothing given, even with atoms in flight" do
    assert Share.give(0, 2, 100.0, 1.0) == 0
    assert Share.give(0, 2, 100.0, 1.0, 100.0) == 0
  end

  test "a single queued atom is not worth moving between equal children" do
    assert Share.give(1, 0, 5.0, 5.0) == 0
  end

  test "a giver that has not finished an atom gives all it has queued" do
    assert Share.give(7, 2, 3.0, nil) == 7
  end

  test "an offerer without a rate counts as fast as the giver" do
    assert Share.give(20, 0, nil, 2.0) == Share.give(20, 0, 2.0, 2.0)
  end

  test "a fast helper keeps atoms from a slow offerer, and sends them with a fast one" do
    assert Share.give(12, 1, 0.5, 1.0) == 4
    assert Share.give(12, 1, 0.5, 1.0, 8.0) == 0
    assert Share.give(12, 1, 2.0, 1.0) == 9
    assert Share.give(12, 1, 2.0, 1.0, 8.0) == 12
  end

  test "a giver with no rate, or a zero one, gives all it has queued" do
    assert Share.give(7, 2, 3.0, 0.0) == 7
    assert Share.give(7, 2, 3.0, nil, 9.0) == 7
  end

  test "long queues are planned in whole rounds, with the same result" do
    # Three children as fast as each other, the giver one atom ahead: the
    # offerer's share is a third, give or take the tie order.
    assert Share.give(1_000_000, 1, 1.0, 1.0, 1.0) == 333_334
    assert Share.give(1_000_000, 1, 3.0, 1.0) == 750_001
  end

  # The plan as written down: one atom at a time to whoever completes one
  # more soonest (giver, offerer, helper on ties).
  defp reference(r, f, o, s, h) do
    o = o || s

    {_g, to_o, to_h} =
      Enum.reduce(1..r//1, {f, 0, 0}, fn _, {g, oo, hh} ->
        times = [{(g + 1) / s, 0}, {(oo + 1) / o, 1}] ++ if(h, do: [{(hh + 1) / h, 2}], else: [])

        case Enum.min(times) do
          {_, 0} -> {g + 1, oo, hh}
          {_, 1} -> {g, oo + 1, hh}
          {_, 2} -> {g, oo, hh + 1}
        end
      end)

    if o > s, do: to_o + to_h, else: to_o
  end

  test "property: the whole-round plan gives what the atom-by-atom plan gives" do
    rate =
      :proper_types.oneof([
        :proper_types.float(0.01, 100.0),
        :proper_types.exactly(1.0),
        :proper_types.exactly(nil)
      ])

    gen =
      {:proper_types.integer(0, 300), :proper_types.integer(0, 2), rate,
       :proper_types.oneof([:proper_types.float(0.01, 100.0), :proper_types.exactly(1.0)]), rate}

    RingTracer.PropErCase.check(
      gen,
      fn {r, f, o, s, h} -> Share.give(r, f, o, s, h) == reference(r, f, o, s, h) end,
      1000
    )
  end

  test "property: never more than queued; more to a faster offerer, fewer from a faster giver" do
    rate = :proper_types.oneof([:proper_types.float(0.01, 100.0), :proper_types.exactly(nil)])

    gen =
      {:proper_types.integer(0, 200), :proper_types.integer(0, 2), rate,
       :proper_types.float(0.01, 100.0), rate}

    RingTracer.PropErCase.check(
      gen,
      fn {r, f, o, s, h} ->
        g = Share.give(r, f, o, s, h)
        o = o || s

        g >= 0 and g <= r and Share.give(r, f, o * 1.5, s, h) >= g and
          Share.give(r, f, o, s * 1.5, h) <= g
      end,
      500
    )
  end
end
