defmodule RingTracer.Strategy.RingTest do
  # The ring strategy's decisions, one message at a time, on a child state
  # built by hand and carried out by the child's own effects: this test
  # process plays every sibling, the parent and the grandchild, and reads
  # what the child sends in its mailbox.
  use ExUnit.Case, async: true

  alias RingTracer.Job.{Child, Directory, Queue, Spec}
  alias RingTracer.Strategy.Ring.HelpOffer
  alias RingTracer.Strategy.Ring

  defp child(fields) do
    me = self()

    spec = %Spec{
      id: make_ref(),
      source: nil,
      settings: nil,
      layout: RingTracer.Layout.new(640, 1, 4, 16),
      caller: me,
      strategy: {Ring, Keyword.get(fields, :options, [])}
    }

    # The ring, published where a child looks its siblings up, for as long
    # as this test's process lives.
    {siblings, fields} = Keyword.pop(fields, :siblings, {me, me, me, me})
    fields = Keyword.delete(fields, :options)
    # the child keeps its queue as a RingTracer.Job.Queue; tests write lists
    fields = Keyword.update(fields, :queue, Queue.new(), &Queue.new/1)
    :ok = Directory.publish(node(), spec.id, me, siblings)
    :ok = Directory.await(spec.id, tuple_size(siblings), 5_000)

    base = %Child{
      spec: spec,
      strategy: Ring,
      index: 1,
      parent: me,
      left: me,
      left_index: 0,
      ring_size: tuple_size(siblings),
      t0: 0,
      grandchild: me,
      queue: Queue.new(),
      in_flight: [],
      current_since: 0,
      done: 4,
      status: :working,
      dead: [],
      strategy_state: %{},
      traffic: %{},
      events: [],
      # 4 atoms traced, 1 work unit per microsecond.
      stats: stats(traced: 4, busy_us: 40_000, work: 40_000)
    }

    struct!(base, fields)
  end

  defp stats(fields) do
    base = Child.new_stats(1, node(), 1, 4)
    {work, fields} = Keyword.pop(fields, :work, 0)
    %{Map.merge(base, Map.new(fields)) | rays: %{base.rays | work: work}}
  end

  # An offer from a sibling as fast as the test's child.
  defp offer(origin, seq \\ 1, via \\ nil),
    do: %HelpOffer{origin: origin, pid: self(), rate: 1.0, seq: seq, via: via}

  defp handle(child, msg), do: Child.strategy_message(child, msg)

  test "an idle child parks an offer, and gives it a share once its own offer brings atoms" do
    idle = child(status: :idle, strategy_state: %{seq: 1, current: 1})
    parked = handle(idle, {:help_offer, offer(2)})

    assert [%HelpOffer{origin: 2}] = parked.strategy_state.parked
    refute_received {:help_offer, _}

    # Our own offer is answered with 6 atoms: two go to the grandchild's pipe,
    # and the parked offerer (as fast as us) gets its share of the rest: of the
    # five we could give, two, as much as the third helper we plan for.
    helped = handle(parked, {:handover, 0, [10, 11, 12, 13, 14, 15]})
    assert_received {:handover, 1, [14, 15]}
    assert Queue.to_list(helped.queue) == [12, 13]
    refute Map.has_key?(helped.strategy_state, :parked)
  end

  test "parked offers it cannot serve go straight to the sibling that just gave" do
    me = self()
    giver = spawn(fn -> receive(do: (m -> send(me, {:relayed, m}))) end)

    idle =
      child(
        status: :idle,
        strategy_state: %{seq: 1, current: 1},
        siblings: {giver, me, me, me}
      )

    parked = handle(idle, {:help_offer, offer(2)})

    # One atom: it goes to the grandchild's pipe, nothing to spare.
    _ = handle(parked, {:handover, 0, [10]})
    assert_receive {:relayed, {:help_offer, %HelpOffer{origin: 2, via: ^me}}}
  end

  test "when its own offer comes back, a child is finished and sends parked offers home" do
    idle = child(status: :idle, strategy_state: %{seq: 1, current: 1})
    child = idle |> handle({:help_offer, offer(2)}) |> handle({:help_offer, offer(3)})

    finished = handle(child, {:help_offer, offer(1)})
    assert finished.status == :finished
    assert_received {:help_offer, %HelpOffer{origin: 2}}
    assert_received {:help_offer, %HelpOffer{origin: 3}}
    assert finished.stats.offers_passed == 2
  end

  test "two idle children never hold each other's offers: a wrapped offer is passed, not parked" do
    # A ring of two: child 0's left is 1, child 1's left is 0. Both are idle
    # with their own offer out.
    c0 = child(index: 0, left_index: 1, status: :working, stats: Child.new_stats(0, node(), 1, 4))
    c1 = child(index: 1, left_index: 0, status: :working)

    c0 = Child.idle(c0)
    assert_received {:help_offer, %HelpOffer{origin: 0, wrapped: true} = from0}
    c1 = Child.idle(c1)
    assert_received {:help_offer, %HelpOffer{origin: 1, wrapped: false} = from1}

    # Child 1 passes child 0's offer (it went past the end of the ring)...
    c1 = handle(c1, {:help_offer, from0})
    refute Map.has_key?(c1.strategy_state, :parked)
    assert_received {:help_offer, %HelpOffer{origin: 0, wrapped: true}}

    # ...and child 0 parks child 1's: one of the two offers always walks on.
    c0 = handle(c0, {:help_offer, from1})
    assert [%HelpOffer{origin: 1}] = c0.strategy_state.parked
  end

  # Tracing its last atom (mean 10 ms per atom, just started).
  # Its atoms take `busy_us / 2` on average (10 ms by default).
  defp on_last_atom(busy_us \\ 20_000) do
    child(
      in_flight: [5],
      current_since: System.monotonic_time(:microsecond),
      stats: stats(traced: 2, busy_us: busy_us)
    )
  end

  # An offer from a sibling that needs 30 ms per atom, 16 hops from home.
  defp far_offer, do: %{offer(2) | hops: 16, atom_us: 30_000}

  test "an offer that walked far waits at a child about to run out, and leaves with its offer" do
    held = handle(on_last_atom(), {:help_offer, far_offer()})
    refute_received {:help_offer, _}
    assert [%HelpOffer{origin: 2, held: true}] = held.strategy_state.held

    # Out of atoms: its own offer and the held one go left in one message.
    out = Child.idle(%{held | in_flight: []})
    assert_received {:help_offers, [%HelpOffer{origin: 1}, %HelpOffer{origin: 2, hops: 17}]}
    refute_received {:help_offer, _}
    assert {1, _bytes} = out.traffic.offer
    refute Map.has_key?(out.strategy_state, :held)
  end

  test "an offer does not wait twice, nor for a child far from done, nor before it walked far" do
    far = far_offer()

    # Far from done: its last atom has about a second left, far more than
    # half of the offerer's 30 ms, however late this test process runs.
    cases = [
      {on_last_atom(), %{far | held: true}},
      {on_last_atom(2_000_000), far},
      {on_last_atom(), %{far | hops: 15}}
    ]

    for {child, o} <- cases do
      passed = handle(child, {:help_offer, o})
      refute Map.has_key?(passed.strategy_state, :held)
      assert_received {:help_offer, %HelpOffer{origin: 2}}
    end
  end

  test "a finished child passes offers on and asks the sender to skip it" do
    me = self()
    sender = spawn(fn -> receive(do: (m -> send(me, {:relayed, m}))) end)
    finished = child(status: :finished, left_index: 0)
    passed = handle(finished, {:help_offer, offer(2, 1, sender)})

    assert_receive {:relayed, {:ring_skip, ^me, ^me, 0}}
    # The offer goes on, and names us as its last sender.
    assert_received {:help_offer, %HelpOffer{origin: 2, via: ^me}}
    assert passed.stats.offers_passed == 1
  end

  test "a sender adopts the skipped child's left only if that child is still its left" do
    gone = spawn(fn -> :ok end)
    next = spawn(fn -> :ok end)
    c = child(left: gone, left_index: 2)

    assert %{left: ^next, left_index: 3} = handle(c, {:ring_skip, gone, next, 3})
    assert %{left: ^gone} = handle(c, {:ring_skip, self(), next, 3})
    # Never to a child known to be dead.
    assert %{left: ^gone} = handle(%{c | dead: [3]}, {:ring_skip, gone, next, 3})
  end

  test "the atom waiting in the grandchild's pipe is given if the grandchild has not started it" do
    gc = spawn(fn -> Process.sleep(:infinity) end)
    busy = child(in_flight: [5, 6], grandchild: gc)

    gave = handle(busy, {:help_offer, offer(2)})
    assert_received {:handover, 1, [6]}
    assert gave.in_flight == [5]
    # The grandchild, reaching atom 6 in its mailbox, will skip it.
    refute RingTracer.Job.Pipe.claim(gc, 6)
  end

  test "an atom the grandchild has already started stays: the offer gets an empty hand-over" do
    gc = spawn(fn -> Process.sleep(:infinity) end)
    assert RingTracer.Job.Pipe.claim(gc, 6)
    busy = child(in_flight: [5, 6], grandchild: gc)

    kept = handle(busy, {:help_offer, offer(2)})
    assert_received {:handover, 1, []}
    assert kept.in_flight == [5, 6]
    RingTracer.Job.Pipe.forget(gc)
  end

  test "adaptive atoms: an offer from a much faster sibling cuts the atom being traced in parts" do
    # Atom 5 in 8 parts, 3 of them started (this test plays the grandchild).
    RingTracer.Job.Pipe.claim(self(), 5)
    for _ <- 1..2, do: assert(RingTracer.Job.Pipe.next(self(), 5))
    busy = child(in_flight: [5], parts: %{5 => 8}, options: [split: true])
    on_exit(fn -> RingTracer.Job.Pipe.forget(self()) end)
    assert Child.view(busy).cuttable == 5

    # 4x faster than us: of the 5 parts not started we keep 1 (a fifth), and
    # the other 4 (half the atom) go to the offerer.
    cut = handle(busy, {:help_offer, %{offer(2) | rate: 4.0}})
    assert_received {:handover, 1, [{5, 1, 2, 2}]}
    assert_received {:gave, 1, 2, [{5, 1, 2, 2}]}
    assert cut.in_flight == [{5, 0, 3, 8}, {5, 3, 4, 8}]
    assert cut.stats.cuts == 1 and cut.stats.splits == 2
    # The grandchild stops after its third part.
    refute RingTracer.Job.Pipe.next(self(), 5)

    # An offer from a sibling as fast as we are does not cut.
    RingTracer.Job.Pipe.claim(self(), 6)
    same = child(in_flight: [6], parts: %{6 => 8}, options: [split: true])
    assert handle(same, {:help_offer, offer(2)}).in_flight == [6]
    refute_received {:handover, _, _}
  end

  test "adaptive atoms: a child traces its atoms in parts once it has heard of a faster sibling" do
    view = fn fields -> struct!(Child.view(child(options: [split: true])), fields) end
    heard = %{heard: [{4.0, 2, 9}]}
    # 1 work unit per µs, 10 ms per atom, 16 rows: the sibling is 4x faster.
    assert Ring.parts(view.(next_rows: 16.0), heard) == 4
    # Not shorter than 2 ms, nor than 4 rows; a power of two.
    assert Ring.parts(view.(next_rows: 16.0, mean_atom_us: 6_000), heard) == 2
    assert Ring.parts(view.(next_rows: 12.0), heard) == 2
    assert Ring.parts(view.(next_rows: 16.0), %{heard: [{64.0, 2, 9}]}) == 4
    assert Ring.parts(view.(next_rows: 64.0, mean_atom_us: 20_000), %{heard: [{64.0, 2, 9}]}) == 8
    # Before the first atom is back: 4 parts (of at least 4 rows).
    assert Ring.parts(view.(next_rows: 16.0, mean_atom_us: nil), %{}) == 4
    assert Ring.parts(view.(next_rows: 8.0, mean_atom_us: nil), %{}) == 2
    # Whole: nobody faster heard of, or whole atoms asked for.
    assert Ring.parts(view.(next_rows: 16.0), %{}) == 1
    assert Ring.parts(view.(next_rows: 16.0), %{heard: [{1.5, 2, 9}]}) == 1
    assert Ring.parts(%{view.(next_rows: 16.0) | options: [split: false]}, heard) == 1
  end

  test "an atom handed over again while the child still holds it is not queued twice" do
    # (PropEr found this: master after a kill, with delayed messages. Twice in
    # a pipe, the second copy met the first one's claim and was skipped, and
    # the child waited for it forever.)
    busy = child(in_flight: [19], queue: [7])
    again = Child.receive_atoms(busy, [19, 7, 8])

    assert (again.in_flight ++ Queue.to_list(again.queue)) |> Enum.sort() == [7, 8, 19]
    # Nobody faster heard of: whole.
    assert_received {:trace, 7}
    refute_received {:trace, 19, _}
    refute_received {:trace, 19}
  end

  test "offers carry on what the children they pass have heard of the fastest siblings" do
    busy = child(in_flight: [5], strategy_state: %{heard: [{5.0, 3, 7}, {0.5, 0, 2}]})
    passed = handle(busy, {:help_offer, %{offer(2) | heard: [{2.0, 1, 1}, {1.0, 2, 4}]}})

    # The offer says child 1 (us) does 2.0 as of its first atom; our own rate
    # after 4 atoms, 1.0, is newer and goes on instead.
    heard = [{5.0, 3, 7}, {1.0, 2, 4}, {1.0, 1, 4}]
    assert_received {:help_offer, %HelpOffer{origin: 2, heard: ^heard}}
    assert passed.strategy_state.heard == heard

    # Our own offer tells the same, and so do the offers held with it.
    held = put_in(passed.strategy_state[:held], [%{offer(3) | heard: []}])
    Child.idle(%{held | in_flight: []})

    assert_received {:help_offers,
                     [
                       %HelpOffer{origin: 1, rate: 1.0, heard: ^heard},
                       %HelpOffer{origin: 3, heard: ^heard}
                     ]}
  end

  test "a dead sibling's rate is no longer told" do
    c = child(dead: [3], strategy_state: %{heard: [{5.0, 3, 7}, {2.0, 0, 2}]})
    Child.idle(c)
    assert_received {:help_offer, %HelpOffer{origin: 1, heard: [{2.0, 0, 2}, {1.0, 1, 4}]}}
  end

  test "a dead sibling is never counted on as the third helper" do
    heard = %{heard: [{50.0, 3, 9}]}
    slow = %{offer(2) | rate: 0.5}

    # Child 3, fifty times faster than us, would take all six atoms we could
    # give: the slow offer is passed on.
    _ =
      handle(
        child(in_flight: [5], queue: Enum.to_list(10..15), strategy_state: heard),
        {:help_offer, slow}
      )

    assert_received {:help_offer, %HelpOffer{origin: 2}}

    # Dead, it is forgotten; a third helper as fast as us leaves the offerer one.
    c = child(in_flight: [5], queue: Enum.to_list(10..15), strategy_state: heard, dead: [3])
    gave = handle(c, {:help_offer, slow})
    assert_received {:handover, 1, [15]}
    assert gave.strategy_state.heard == [{1.0, 1, 4}]
  end

  test "a working child with nothing to spare passes the offer to its left" do
    busy = child(in_flight: [5])
    _ = handle(busy, {:help_offer, offer(2)})
    assert_received {:help_offer, %HelpOffer{origin: 2}}
  end

  describe "aiming" do
    # A child that aims (`aim: true`), with job time starting now.
    defp aiming(fields) do
      child(
        fields
        |> Keyword.put_new(:t0, System.system_time(:microsecond))
        |> Keyword.put(:options, aim: true)
      )
    end

    # A sibling that tells the test what reached it.
    defp relay(tag) do
      me = self()
      spawn(fn -> receive(do: (m -> send(me, {tag, m}))) end)
    end

    test "an idle child sends its offer straight to the sibling expected to end last" do
      three = relay(:three)
      # Sibling 3 said, just now, that it holds 8 queued atoms and should end
      # in a second; sibling 2 ends sooner. Our left sibling is 0.
      loads = [{3, 1_000_000, 0, 8}, {2, 500_000, 0, 8}]
      c = aiming(siblings: {self(), self(), self(), three}, strategy_state: %{loads: loads})

      offered = Child.idle(c)
      assert_receive {:three, {:help_offer, %HelpOffer{origin: 1, aimed: 3} = o}}
      # It carries what we know: sibling 3 first, and our own load among them.
      assert [{3, 1_000_000, 0, 8} | _] = o.loads
      assert Enum.any?(o.loads, &(elem(&1, 0) == 1))
      assert offered.status == :idle
      refute_received {:help_offer, _}
    end

    test "with nobody expected to have atoms queued, the offer goes to the left sibling" do
      # Sibling 3 ends late, but has started its last queued atom since it said so.
      loads = [{3, 1_000_000, -900_000, 1}]
      Child.idle(aiming(strategy_state: %{loads: loads}))
      assert_received {:help_offer, %HelpOffer{origin: 1, aimed: nil}}
    end

    test "without aiming, offers go left and carry no loads" do
      Child.idle(child(strategy_state: %{loads: [{3, 1_000_000, 0, 8}]}))
      assert_received {:help_offer, %HelpOffer{origin: 1, aimed: nil, loads: []}}
    end

    test "an aimed offer that finds nothing walks the ring from its origin's left sibling" do
      target_left = relay(:target_left)
      origin_left = relay(:origin_left)
      # Tracing its last atom: nothing to give.
      target = aiming(index: 3, left: target_left, left_index: 2, in_flight: [5])
      aimed = %{offer(1) | aimed: 3, home_left: {origin_left, 0}, wrapped: true, hops: 1}
      _ = handle(target, {:help_offer, aimed})

      # As if child 1 had sent it to child 0 itself, with our load first.
      me = self()

      assert_receive {:origin_left,
                      {:help_offer,
                       %HelpOffer{origin: 1, aimed: nil, hops: 1, wrapped: false, via: ^me} = o}}

      assert [{3, _, _, 0} | _] = o.loads
      refute_receive {:target_left, _}, 50
      refute_received {:help_offer, _}
    end

    test "a miss goes back to its origin if the origin's left sibling is dead" do
      target = aiming(index: 3, left_index: 2, in_flight: [5], dead: [0])
      _ = handle(target, {:help_offer, %{offer(1) | aimed: 3, home_left: {relay(:gone), 0}}})
      assert_received {:help_offer, %HelpOffer{origin: 1, aimed: 3, loads: [{3, _, _, 0} | _]}}
    end

    test "an aimed offer that comes home is followed by one that walks the ring" do
      home = aiming(status: :idle, strategy_state: %{seq: 1, current: 1})
      back = %{offer(1) | aimed: 3, loads: [{3, 100, 50, 0}]}
      walking = handle(home, {:help_offer, back})

      assert_received {:help_offer, %HelpOffer{origin: 1, seq: 2, aimed: nil}}
      assert walking.status == :idle
      # Sibling 3 has nothing to give, and we know it now.
      assert {3, 100, 50, 0} in walking.strategy_state.loads
    end

    test "a giver tells the offerer its load, just lowered, in the hand-over" do
      gc = spawn(fn -> Process.sleep(:infinity) end)
      busy = aiming(in_flight: [5], queue: Enum.to_list(10..15), grandchild: gc)
      gave = handle(busy, {:help_offer, offer(2)})

      assert_received {:handover, 1, atoms, [{1, _end, _at, queued} | _]}
      assert queued == Queue.size(gave.queue)
      assert length(atoms) + queued == 6
    end
  end

  test "adaptive atoms: children of unequal speeds trace pieces that tile the image; split: false (the default) keeps atoms whole" do
    # Eight atoms a child, 10 ms each at full speed: the job lasts long
    # enough that hand-overs come after both sides have measured a rate, even
    # when the schedulers are busy with other work.
    job = [children: 8, atoms: 8, speeds: Enum.to_list(1..8), costs: 10_000]
    n = job[:children] * job[:atoms]
    {:ok, r} = RingTracer.simulate([strategy: :ring, split: true] ++ job)
    ids = Enum.map(r.atoms, & &1.atom)
    layout = RingTracer.Layout.new(n, 1, job[:children], job[:atoms])
    assert Enum.any?(ids, &is_tuple/1)
    assert ids == Enum.uniq(ids)
    assert RingTracer.Job.Coverage.tiles?(layout, ids)
    assert length(ids) == n + Enum.sum(Enum.map(r.children, & &1.splits))
    assert r.messages.result.count == length(ids)

    for opts <- [[split: false], []] do
      {:ok, fixed} = RingTracer.simulate([strategy: :ring] ++ opts ++ job)
      assert Enum.sort(Enum.map(fixed.atoms, & &1.atom)) == Enum.to_list(0..(n - 1))
      assert Enum.all?(fixed.children, &(&1.splits == 0))
    end
  end
end
