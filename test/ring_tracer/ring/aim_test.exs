defmodule RingTracer.Strategy.Ring.AimTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Strategy.Ring.Aim

  alias RingTracer.Layout
  alias RingTracer.Strategy.Ring.Aim

  test "learn keeps the newest report per sibling and at most eight, latest-ending first" do
    old = for i <- 0..9, do: {i, 1_000 * i, 10, 2}
    known = Aim.learn(old, [{0, 50_000, 20, 5}, {9, 1, 5, 0}])

    assert length(known) == 8
    assert hd(known) == {0, 50_000, 20, 5}
    # Sibling 9's older report (at 5) lost to the one it had (at 10).
    assert {9, 9_000, 10, 2} in known
    assert Enum.map(known, &elem(&1, 1)) == Enum.sort(Enum.map(known, &elem(&1, 1)), :desc)
  end

  test "the board sees each child's untraced atoms over its delivered rate" do
    # 2 children x 3 atoms; child 0 traced atom 0 (work 10) and child 1
    # traced atom 3 (work 30) by time 10: rates 1 and 3 work units per us.
    layout = Layout.new(6, 1, 2, 3)
    work = {10, 20, 30, 30, 60, 90}
    {loads, to} = Aim.board(layout, work, %{0 => 0, 3 => 1}, 10)

    # Child 0 holds 50 units (20 + 30): 50 us; child 1 holds 150: 50 us too,
    # a tie broken by index.
    assert loads == [{0, 60, 10, 2}, {1, 60, 10, 2}]
    assert Enum.sort(to) == [0, 1]

    # An atom a sibling traced for child 0 is no longer child 0's to give.
    {loads, _} = Aim.board(layout, work, %{0 => 0, 1 => 1, 3 => 1}, 10)
    assert {0, 40, 10, 1} in loads
  end

  test "the board goes to the two children expected to run out first" do
    layout = Layout.new(8, 1, 4, 2)
    work = {1, 1, 1, 9, 1, 99, 1, 5}
    traced_by = %{0 => 0, 2 => 1, 4 => 2, 6 => 3}
    {[latest | _], to} = Aim.board(layout, work, traced_by, 1)

    assert elem(latest, 0) == 2
    assert Enum.sort(to) == [0, 3]
  end

  test "property: the target is a live sibling other than self and the left one, queued, ending last" do
    import :proper_types

    load = {integer(0, 7), integer(0, 100_000), integer(0, 50_000), integer(0, 6)}
    gen = {list(load), integer(0, 7), integer(0, 7), list(integer(0, 7)), integer(0, 60_000)}

    RingTracer.PropErCase.check(
      gen,
      fn {known, index, left, dead, now} ->
        known = Aim.learn([], known)
        view = %{index: index, left_index: left, dead: dead, now: now, min_us: 1_000}

        eligible =
          for {i, _, _, _} = l <- known,
              i != index and i not in dead and Aim.queued?(l, now),
              do: l

        case Aim.target(known, view) do
          nil ->
            # Either nobody is eligible, or the latest-ending one is our
            # left sibling, or it ends too soon to be worth the detour.
            case Enum.max_by(eligible, &elem(&1, 1), fn -> nil end) do
              nil -> true
              {i, end_us, _, _} -> i == left or end_us <= now + 1_000
            end

          t ->
            {^t, end_us, _, _} = List.keyfind(known, t, 0)

            t != index and t != left and t not in dead and
              Aim.queued?(List.keyfind(known, t, 0), now) and end_us > now + 1_000 and
              Enum.all?(eligible, &(elem(&1, 1) <= end_us))
        end
      end,
      1000
    )
  end
end
