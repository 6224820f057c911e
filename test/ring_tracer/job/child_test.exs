defmodule RingTracer.Job.ChildTest do
  # How a child carries out its strategy's effects: messages handed to its
  # `handle_info/2` (as its process would get them) on a child state built
  # by hand, with the ring as its strategy. This test process plays every
  # sibling, the parent and the grandchild, and reads what the child sends
  # in its mailbox. The ring's decisions themselves are
  # `RingTracer.Strategy.RingTest`'s.
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Stats

  alias RingTracer.Job.{Child, Directory, Pipe, Queue, Spec, Stats}
  alias RingTracer.Strategy.Ring
  alias RingTracer.Strategy.Ring.HelpOffer

  @layout RingTracer.Layout.new(640, 1, 4, 16)

  defp child(fields) do
    me = self()
    {options, fields} = Keyword.pop(fields, :options, [])
    {:ok, options} = Ring.options(Keyword.merge([aim: false, split: true], options), @layout)

    spec = %Spec{
      id: make_ref(),
      source: nil,
      settings: nil,
      layout: @layout,
      caller: me,
      strategy: {Ring, options}
    }

    # The ring, published where a child looks its siblings up, for as long
    # as this test's process lives.
    siblings = {me, me, me, me}
    :ok = Directory.publish(node(), spec.id, me, siblings)
    :ok = Directory.await(spec.id, tuple_size(siblings), 5_000)
    # the child keeps its queue as a RingTracer.Job.Queue; tests write lists
    fields = Keyword.update(fields, :queue, Queue.new(), &Queue.new/1)

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
      strategy_state: %RingTracer.Strategy.Ring.State{},
      traffic: %{},
      events: [],
      # 4 atoms traced, 1 work unit per microsecond.
      stats: stats(traced: 4, busy_us: 40_000, work: 40_000)
    }

    struct!(base, fields)
  end

  defp stats(fields) do
    base = Stats.new(1, node(), 1, 4)
    {work, fields} = Keyword.pop(fields, :work, 0)
    %{struct!(base, fields) | rays: %{base.rays | work: work}}
  end

  # An offer from a sibling as fast as the child.
  defp offer(origin, seq \\ 1), do: %HelpOffer{origin: origin, pid: self(), rate: 1.0, seq: seq}

  defp handle(child, message) do
    {:noreply, child} = Child.handle_info(message, child)
    child
  end

  # The grandchild's report of atom `atom`, traced just now.
  defp traced(atom) do
    now = System.system_time(:microsecond)
    timing = %{started_at: now, ended_at: now, trace_us: 0}
    {:traced, self(), atom, <<>>, RingTracer.Kernel.no_rays(), timing}
  end

  test "a child gives its farthest atoms, once atoms come to the offers it parked while idle" do
    idle =
      child(status: :idle, strategy_state: %RingTracer.Strategy.Ring.State{seq: 1, current: 1})

    parked = handle(idle, {:help_offer, offer(2)})
    refute_received {:help_offer, _}

    # Its own offer is answered with 6 atoms: two go to the grandchild's
    # pipe, and the parked offerer gets the last two of the rest.
    helped = handle(parked, {:handover, 0, [10, 11, 12, 13, 14, 15]})
    assert_received {:got, 0, 1, [10, 11, 12, 13, 14, 15]}
    assert_received {:trace, 10}
    assert_received {:trace, 11}
    assert_received {:handover, 1, [14, 15]}
    assert_received {:gave, 1, 2, [14, 15]}
    assert Queue.to_list(helped.queue) == [12, 13]
    assert helped.stats.given == 2 and helped.stats.offers_consumed == 1
  end

  test "its own offer back, a child is finished and counts the parked offers it sends home" do
    idle =
      child(status: :idle, strategy_state: %RingTracer.Strategy.Ring.State{seq: 1, current: 1})

    c = idle |> handle({:help_offer, offer(2)}) |> handle({:help_offer, offer(3)})

    finished = handle(c, {:help_offer, offer(1)})
    assert finished.status == :finished
    assert_received {:help_offer, %HelpOffer{origin: 2}}
    assert_received {:help_offer, %HelpOffer{origin: 3}}
    assert finished.stats.offers_passed == 2
    assert {2, _bytes} = finished.traffic.offer
  end

  test "out of atoms, a child's offer and the ones it held leave in one message, counted once" do
    far = %{offer(2) | hops: 16, atom_us: 30_000}

    on_last_atom =
      child(
        in_flight: [5],
        current_since: System.monotonic_time(:microsecond),
        stats: stats(traced: 2, busy_us: 20_000)
      )

    held = handle(on_last_atom, {:help_offer, far})
    refute_received {:help_offer, _}

    # Its last atom is traced: its pixels go to the parent, and it is idle.
    out = handle(held, traced(5))
    assert_received {:atom_done, 1, 5, <<>>, _rays, 0}
    assert_received {:help_offers, [%HelpOffer{origin: 1}, %HelpOffer{origin: 2, hops: 17}]}
    refute_received {:help_offer, _}
    assert out.status == :idle
    assert {1, _bytes} = out.traffic.offer
    assert out.stats.offers_sent == 1 and out.stats.traced == 3
  end

  test "the atom waiting in the grandchild's pipe is given if the grandchild has not started it" do
    gc = spawn(fn -> Process.sleep(:infinity) end)
    busy = child(in_flight: [5, 6], grandchild: gc)

    gave = handle(busy, {:help_offer, offer(2)})
    assert_received {:handover, 1, [6]}
    assert gave.in_flight == [5]
    # The grandchild, reaching atom 6 in its mailbox, will skip it.
    refute Pipe.claim(gc, 6)
  end

  test "an atom the grandchild has already started stays: the offer gets an empty hand-over" do
    gc = spawn(fn -> Process.sleep(:infinity) end)
    assert Pipe.claim(gc, 6)
    busy = child(in_flight: [5, 6], grandchild: gc)

    kept = handle(busy, {:help_offer, offer(2)})
    assert_received {:handover, 1, []}
    refute_received {:gave, _, _, _}
    assert kept.in_flight == [5, 6]
    Pipe.forget(gc)
  end

  test "adaptive atoms: a cut queues the parts kept and hands over the rest" do
    # Atom 5 in 8 parts, 3 of them started (this test plays the grandchild).
    Pipe.claim(self(), 5)
    for _ <- 1..2, do: assert(Pipe.next(self(), 5))
    on_exit(fn -> Pipe.forget(self()) end)
    busy = child(in_flight: [5], parts: %{5 => 8})

    # 4x faster than us: of the 5 parts not started (the child's view says
    # so) we keep 1 (a fifth), and the other 4 (half the atom) go to the
    # offerer.
    cut = handle(busy, {:help_offer, %{offer(2) | rate: 4.0}})
    assert_received {:handover, 1, [{5, 1, 2, 2}]}
    assert_received {:gave, 1, 2, [{5, 1, 2, 2}]}
    assert cut.in_flight == [{5, 0, 3, 8}, {5, 3, 4, 8}]
    assert cut.stats.cuts == 1 and cut.stats.splits == 2
    # The grandchild stops after its third part.
    refute Pipe.next(self(), 5)

    # An offer from a sibling as fast as we are does not cut.
    Pipe.claim(self(), 6)
    same = child(in_flight: [6], parts: %{6 => 8})
    assert handle(same, {:help_offer, offer(2)}).in_flight == [6]
    refute_received {:handover, _, _}
  end

  test "an atom handed over again while the child still holds it is not queued twice" do
    # (PropEr found this: master after a kill, with delayed messages. Twice in
    # a pipe, the second copy met the first one's claim and was skipped, and
    # the child waited for it forever.)
    busy = child(in_flight: [19], queue: [7])
    again = handle(busy, {:handover, 0, [19, 7, 8]})

    assert (again.in_flight ++ Queue.to_list(again.queue)) |> Enum.sort() == [7, 8, 19]
    # Nobody faster heard of: whole.
    assert_received {:trace, 7}
    refute_received {:trace, 19, _}
    refute_received {:trace, 19}
  end

  test "a hand-over carries the news of an aiming giver: its load, just lowered" do
    gc = spawn(fn -> Process.sleep(:infinity) end)

    busy =
      child(
        in_flight: [5],
        queue: Enum.to_list(10..15),
        grandchild: gc,
        t0: System.system_time(:microsecond),
        options: [aim: true]
      )

    gave = handle(busy, {:help_offer, offer(2)})
    assert_received {:handover, 1, atoms, [{1, _end, _at, queued} | _]}
    assert queued == Queue.size(gave.queue)
    assert length(atoms) + queued == 6
  end

  test "a sender adopts the left sibling a finished child names" do
    gone = spawn(fn -> :ok end)
    next = spawn(fn -> :ok end)
    c = child(left: gone, left_index: 2)
    assert %{left: ^next, left_index: 3} = handle(c, {:ring_skip, gone, next, 3})
  end
end
