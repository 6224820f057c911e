defmodule RingTracer.Ring.ShareTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Ring.Share

  alias RingTracer.Ring.Share

  test "equal speeds split what is left in half" do
    assert Share.give(20, 0, 10, 10) == 10
  end

  test "a slower offerer gets fewer atoms than a faster one" do
    slow = Share.give(30, 2, 2, 8)
    fast = Share.give(30, 2, 8, 2)
    assert slow < fast
    assert slow == div(32 * 2, 10)
    assert fast == 25
  end

  test "nothing queued, nothing given, even with atoms in flight" do
    assert Share.give(0, 2, 100, 1) == 0
  end

  test "a single queued atom is not worth moving between equal children" do
    assert Share.give(1, 0, 5, 5) == 0
  end

  test "a giver that has computed nothing gives all it has queued" do
    assert Share.give(7, 2, 3, 0) == 7
  end

  test "property: never more than queued, and monotone in the offerer's speed" do
    gen =
      {:proper_types.integer(0, 500), :proper_types.integer(0, 2), :proper_types.integer(0, 500),
       :proper_types.integer(0, 500)}

    RingTracer.PropErCase.check(
      gen,
      fn {r, f, o, s} ->
        g = Share.give(r, f, o, s)
        g >= 0 and g <= r and Share.give(r, f, o + 1, s) >= g and Share.give(r, f, o, s + 1) <= g
      end,
      500
    )
  end
end
