defmodule RingTracer.Job.LedgerTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Ledger

  alias RingTracer.Job.Ledger
  alias RingTracer.Layout

  test "the master strategy's children start with nothing; the parent's hand-outs count" do
    ledger = Ledger.new(Layout.new(8, 8, 2, 4), RingTracer.Strategy.Master)
    assert Ledger.held(ledger, 0) == []
    ledger = Ledger.moved(ledger, :parent, 0, [5, 2])
    assert Ledger.held(ledger, 0) == [2, 5]
    assert Ledger.held(ledger, 1) == []
  end

  test "atoms given to a dead child are on nobody's account" do
    ledger = Ledger.new(Layout.new(8, 8, 2, 2), RingTracer.Strategy.Ring)
    ledger = ledger |> Ledger.forget(1) |> Ledger.moved(0, :nobody, [1])
    assert Ledger.held(ledger, 0) == [0]
  end

  # Atoms move between children at random (each move is a hand-over, and the
  # giver's report to the parent); the reports reach the parent in any order.
  # At every moment, each atom's real holder either may hold it by the
  # ledger or has a report of receiving it still on its way: so a death is
  # always covered, at once or when that report arrives. Once every report
  # has arrived, the ledger is exact.
  test "property: whatever order the reports arrive in, no atom is ever unaccounted for" do
    import :proper_types

    gen = {integer(2, 6), integer(1, 4), list({integer(0, 1000), integer(0, 1000), integer()})}

    RingTracer.PropErCase.check(
      gen,
      fn {n, k, moves} ->
        {layout, atoms, truth} = start(n, k)

        {truth, reports} =
          Enum.reduce(moves, {truth, []}, fn {a, to, key}, {truth, reports} ->
            a = rem(a, atoms)
            {from, to} = {truth[a], rem(to, n)}

            if from == to,
              do: {truth, reports},
              else: {Map.put(truth, a, to), [{key, {from, to, a}} | reports]}
          end)

        arrival = reports |> Enum.sort() |> Enum.map(&elem(&1, 1))

        {ledger, ok} =
          arrival
          |> Enum.with_index(1)
          |> Enum.reduce({Ledger.new(layout, RingTracer.Strategy.Ring), true}, fn {{f, t, a}, i},
                                                                                  {l, ok} ->
            l = Ledger.moved(l, f, t, [a])
            pending = Enum.drop(arrival, i)

            covered =
              Enum.all?(truth, fn {atom, holder} ->
                atom in Ledger.held(l, holder) or
                  Enum.any?(pending, &match?({_, ^holder, ^atom}, &1))
              end)

            {l, ok and covered}
          end)

        exact =
          Enum.all?(0..(n - 1), fn c ->
            Ledger.held(ledger, c) == for({a, ^c} <- Enum.sort(truth), do: a)
          end)

        ok and exact
      end,
      300
    )
  end

  # Hand-overs between children at random, some lost on the way (the
  # giver's node froze with the message in its buffers): the giver's
  # report always reaches the parent, the receiver's confirmation only
  # when the atoms arrived, all in any order. Once every report is in, an
  # atom that arrived is held by its holder and in transit with nobody; an
  # atom lost on the way is in transit with its giver, to be handed out
  # again when the giver dies.
  test "property: a hand-over lost on the way stays in transit with its giver" do
    import :proper_types

    gen =
      {integer(2, 6), integer(1, 4),
       list({integer(0, 1000), integer(0, 1000), boolean(), integer(), integer()})}

    RingTracer.PropErCase.check(
      gen,
      fn {n, k, moves} ->
        {layout, atoms, truth} = start(n, k)

        {truth, reports} =
          Enum.reduce(moves, {truth, []}, fn {a, to, lost, k1, k2}, {truth, reports} ->
            a = rem(a, atoms)
            to = rem(to, n)

            case truth[a] do
              {:lost, _} ->
                {truth, reports}

              ^to ->
                {truth, reports}

              from ->
                gave = {k1, {:gave, from, to, a}}

                if lost,
                  do: {Map.put(truth, a, {:lost, from}), [gave | reports]},
                  else: {Map.put(truth, a, to), [gave, {k2, {:got, from, to, a}} | reports]}
            end
          end)

        ledger =
          reports
          |> Enum.sort()
          |> Enum.reduce(Ledger.new(layout, RingTracer.Strategy.Ring), fn
            {_, {:gave, f, t, a}}, l -> Ledger.moved(l, f, t, [a])
            {_, {:got, f, _t, a}}, l -> Ledger.received(l, f, [a])
          end)

        in_transit = Map.new(0..(n - 1), &{&1, Ledger.in_transit(ledger, &1)})

        Enum.all?(truth, fn
          {a, {:lost, from}} ->
            a in in_transit[from]

          {a, holder} ->
            a in Ledger.held(ledger, holder) and
              not Enum.any?(in_transit, fn {_, l} -> a in l end)
        end)
      end,
      300
    )
  end

  # A ring of `n` children of `k` atoms: its layout, its atom count, and
  # each atom's holder at the start (its strip's owner).
  defp start(n, k) do
    layout = Layout.new(64, 64, n, k)

    {layout, Layout.atom_count(layout),
     Map.new(Layout.atoms(layout), &{&1, Layout.owner(layout, &1)})}
  end
end
