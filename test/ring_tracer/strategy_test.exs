defmodule RingTracer.StrategyTest do
  use ExUnit.Case, async: false
  doctest RingTracer.Strategy
  doctest RingTracer.Strategies

  alias RingTracer.TestScenes

  @scene "balls_s1.nff"

  test "every strategy gives the byte-identical image, with speeds too" do
    reference = TestScenes.reference(@scene, 40, 30)

    for strategy <- RingTracer.Strategies.names(),
        speeds <- [[], [1, 3, 1]],
        # adaptive atoms are the ring's
        split <- if(strategy == :ring, do: [false, true], else: [false]) do
      {:ok, result} =
        RingTracer.render(TestScenes.path(@scene),
          strategy: if(split, do: {:ring, split: true}, else: strategy),
          speeds: speeds,
          children: 3,
          atoms: 6,
          width: 40,
          height: 30
        )

      assert result.pixels == reference, "#{strategy} #{inspect(speeds)} split: #{split}"

      if split do
        # Adaptive atoms (the ring's): one record and one result message
        # per atom or piece, the pieces tiling the image once.
        assert tiles?(3, 6, result)
        assert result.messages.result.count == length(result.atoms)
      else
        assert length(result.atoms) == 18
        assert Enum.sort(Enum.map(result.atoms, & &1.atom)) == Enum.to_list(0..17)
        assert result.messages.result.count == 18
      end
    end
  end

  test "the interleaved layout gives the same image; each child starts with atoms i, i + N, ..." do
    reference = TestScenes.reference(@scene, 40, 30)

    for strategy <- RingTracer.Strategies.names() do
      {:ok, result} =
        RingTracer.render(TestScenes.path(@scene),
          strategy: strategy,
          layout: :interleaved,
          speeds: [1, 3, 1],
          children: 3,
          atoms: 6,
          width: 40,
          height: 30
        )

      assert result.pixels == reference, "#{strategy}"
      assert result.layout == :interleaved
      # Pieces of an atom (adaptive atoms) have its owner.
      assert Enum.all?(result.atoms, &(&1.owner == rem(RingTracer.Layout.base(&1.atom), 3)))
      # The master owns every atom itself and hands them out in image order.
      own = if strategy == :master, do: 0, else: 6
      assert Enum.all?(result.children, &(&1.own == own)), "#{strategy}"

      if strategy == :static, do: assert(Enum.all?(result.atoms, &(&1.child == &1.owner)))
    end
  end

  test "static never hands atoms over; master hands every atom out; ring counts balance" do
    path = TestScenes.path(@scene)

    {:ok, static} =
      RingTracer.render(path, strategy: :static, children: 3, atoms: 4, width: 30, height: 20)

    assert Enum.all?(static.atoms, &(&1.owner == &1.child))
    refute Map.has_key?(static.messages, :handover)

    {:ok, master} =
      RingTracer.render(path, strategy: :master, children: 3, atoms: 4, width: 30, height: 20)

    assert master.messages.handover.count == 12

    {:ok, ring} =
      RingTracer.render(path,
        strategy: :ring,
        children: 3,
        atoms: 4,
        width: 30,
        height: 20,
        speeds: [1, 1, 6]
      )

    given = Enum.sum(Enum.map(ring.children, & &1.given))
    assert given == Enum.sum(Enum.map(ring.children, & &1.received))

    assert Map.get(ring.messages, :handover, %{count: 0}).count ==
             Enum.sum(Enum.map(ring.children, & &1.offers_consumed))

    assert ring.messages.offer.count ==
             Enum.sum(Enum.map(ring.children, &(&1.offers_sent + &1.offers_passed)))
  end

  test "a slow child is helped by the ring: it traces fewer atoms than it owns" do
    {:ok, result} =
      RingTracer.render(TestScenes.path("balls_s2.nff"),
        children: 4,
        atoms: 12,
        width: 96,
        height: 96,
        speeds: [1, 1, 6, 1]
      )

    slow = Enum.at(result.children, 2)
    assert slow.given > 0
    assert slow.traced < slow.own
  end

  test "message counts in the stats equal the sends a tracer observes" do
    # hold_after: 1, so that held offers leave in shared messages too.
    {result, observed} =
      render_traced(
        children: 6,
        atoms: 6,
        speeds: [1, 5, 1, 1, 3, 1],
        strategy: {:ring, hold_after: 1}
      )

    assert observed[:result] == result.messages.result.count
    assert Map.get(observed, :offer, 0) == Map.get(result.messages, :offer, %{count: 0}).count

    assert Map.get(observed, :handover, 0) ==
             Map.get(result.messages, :handover, %{count: 0}).count
  end

  test "aiming: the parent sends its board to two children, and the image does not change" do
    reference = TestScenes.reference(@scene, 40, 30)

    for {aim, boards} <- [{true, 2}, {false, 0}] do
      {result, _observed} =
        render_traced(children: 5, atoms: 6, speeds: [1, 3, 1, 2, 1], strategy: {:ring, aim: aim})

      assert result.pixels == reference

      # The board waits for the work preview and for one atom from every
      # child: on the simulated kernel the preview is instant and every atom
      # takes 20 ms, so the board always leaves while work remains (a tiny
      # native render can end before its preview, on a busy machine).
      {:ok, _, observed} =
        traced(fn ->
          RingTracer.simulate(
            children: 5,
            atoms: 6,
            costs: 20_000,
            speeds: [1, 3, 1, 2, 1],
            strategy: {:ring, aim: aim}
          )
        end)

      assert Map.get(observed, :board, 0) == boards, "aim: #{aim}"
    end
  end

  test "the ring aims on strips, not on interleaved strips unless asked; no other strategy aims" do
    for {layout, opts, aimed?} <- [
          {:strips, [], true},
          {:interleaved, [], false},
          {:interleaved, [strategy: {:ring, aim: true}], true},
          {:strips, [strategy: {:ring, aim: false}], false},
          {:strips, [strategy: :master], false}
        ] do
      {:ok, result} =
        RingTracer.simulate([children: 3, atoms: 4, costs: 500, layout: layout] ++ opts)

      assert Keyword.get(result.strategy_options, :aim, false) == aimed?,
             "#{layout} #{inspect(opts)}"
    end
  end

  test "a result names its strategy and the options it ran with, defaults filled in" do
    {:ok, ring} = RingTracer.simulate(children: 2, atoms: 2, costs: 100)
    assert ring.strategy == :ring
    assert ring.strategy_options[:hold_after] == 16
    assert ring.strategy_options[:split] == false

    {:ok, split} =
      RingTracer.simulate(children: 2, atoms: 2, costs: 100, strategy: {:ring, split: true})

    assert {split.strategy, split.strategy_options[:split]} == {:ring, true}

    {:ok, steal} = RingTracer.simulate(children: 2, atoms: 2, costs: 100, strategy: :steal)
    assert {steal.strategy, steal.strategy_options} == {:steal, []}
  end

  test "a strategy's options are its own to check; the ring's moved from render/2's" do
    for {opts, message} <- [
          {[split: true],
           "option :split is the ring's own: give it with the strategy, " <>
             "strategy: {:ring, [split: true]}"},
          {[hold_after: 2], "strategy: {:ring, [hold_after: 2]}"},
          {[aim: false], "strategy: {:ring, [aim: false]}"},
          {[strategy: {:ring, hold_after: 0}],
           "the ring's :hold_after must be a positive integer"},
          {[strategy: {:ring, aim: :yes}], "the ring's :aim must be a boolean"},
          {[strategy: {:ring, hold: 2}], "the ring has no option :hold"},
          {[strategy: {:steal, split: true}], "strategy :steal takes no options"},
          {[strategy: {:lottery, []}], "RingTracer.Strategy"},
          {[strategy: {String, []}], "String is not a RingTracer.Strategy"},
          {[strategy: {:ring, [:split]}], "option :strategy"}
        ] do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: m}} =
               RingTracer.simulate([children: 2, atoms: 2] ++ opts)

      assert m =~ message, "#{inspect(opts)}: #{m}"
    end
  end

  # A 40x30 render with every send by the job's processes traced: the
  # result, and the sends observed, by kind.
  defp render_traced(opts) do
    {:ok, result, observed} =
      traced(fn -> RingTracer.render(TestScenes.path(@scene), [width: 40, height: 30] ++ opts) end)

    {result, observed}
  end

  defp traced(fun) do
    :erlang.trace(:new_processes, true, [:send])
    {:ok, result} = fun.()
    :erlang.trace(:new_processes, false, [:send])
    {:ok, result, collect_sends(%{})}
  end

  # A send to a process that has already exited is traced apart: as the job
  # stops, a child may still pass an offer to a sibling that stopped first,
  # and that offer was sent (and counted) all the same.
  defp collect_sends(acc) do
    receive do
      {:trace, _from, event, msg, _to} when event in [:send, :send_to_non_existing_process] ->
        collect_sends(Map.update(acc, kind(msg), 1, &(&1 + 1)))
    after
      200 -> acc
    end
  end

  defp kind({:atom_done, _, _, _, _, _}), do: :result
  defp kind({:help_offer, _}), do: :offer
  defp kind({:help_offers, _}), do: :offer
  defp kind({:handover, _, _}), do: :handover
  defp kind({:handover, _, _, _}), do: :handover
  defp kind({:loads, _}), do: :board
  defp kind(_), do: :other

  test "idle children park offers: the end of a 256-child job costs far fewer than N² offer messages" do
    # Without parking, every child's last offer travels the whole ring
    # (about 12,000 offer messages here); with parking and holding,
    # 1,900-2,300.
    {:ok, result} = RingTracer.simulate(children: 256, atoms: 8, costs: 5000, speeds: [1, 2, 3])
    assert tiles?(256, 8, result)
    assert result.messages.offer.count < div(256 * 256, 16)
  end

  @tag :slow
  test "a 1024-child simulated ring finishes with every atom once" do
    {:ok, result} = RingTracer.simulate(children: 1024, atoms: 4, costs: 2000, speeds: [1, 2, 3])
    assert tiles?(1024, 4, result)
  end

  # One record per atom, or per piece of one (adaptive atoms), tiling the
  # image exactly once.
  defp tiles?(n, k, result) do
    ids = Enum.map(result.atoms, & &1.atom)

    ids == Enum.uniq(ids) and
      RingTracer.Job.Coverage.tiles?(RingTracer.Layout.new(n * k, 1, n, k), ids)
  end
end
