defmodule RingTracer.Strategy.RingTest do
  # The ring strategy's decisions, one callback at a time, on a view built
  # by hand: what it answers is its new state and a list of effects (data).
  # How a child carries those effects out (the pipe, cuts, queues, counters)
  # is `RingTracer.Job.ChildTest`'s.
  use ExUnit.Case, async: true
  doctest RingTracer.Strategy.Ring.Options

  alias RingTracer.Strategy.Ring
  alias RingTracer.Strategy.Ring.{HelpOffer, State}
  alias RingTracer.Strategy.View

  @layout RingTracer.Layout.new(640, 1, 4, 16)

  # The ring's options, completed by the ring itself. These tests were
  # written for a ring that cuts atoms (`split: true`) and does not aim,
  # unless a test says otherwise.
  defp options(extra) do
    {:ok, options} = Ring.options(Keyword.merge([aim: false, split: true], extra), @layout)
    options
  end

  # Child 1 of a ring of 4, its left sibling 0 (this test process plays
  # every sibling), working: 4 atoms traced at 1 work unit per microsecond,
  # 10 ms each.
  defp view(fields \\ []) do
    {options, fields} = Keyword.pop(fields, :options, [])

    struct!(
      %View{
        job: make_ref(),
        index: 1,
        pid: self(),
        ring_size: 4,
        left: self(),
        left_index: 0,
        status: :working,
        options: options(options),
        done: 4,
        rate: 1.0,
        mean_atom_us: 10_000
      },
      fields
    )
  end

  # An offer from a sibling as fast as the view's child.
  defp offer(origin, seq \\ 1, via \\ nil),
    do: %HelpOffer{origin: origin, pid: self(), rate: 1.0, seq: seq, via: via}

  defp handle({view, state}, message), do: Ring.handle_message(message, view, state)

  # The messages the effects send, as `{to, message}`.
  defp sends(effects), do: for({:send, to, _kind, message} <- effects, do: {to, message})

  defp offers_to(effects, to), do: for({^to, message} <- sends(effects), do: message)

  test "an idle child parks an offer, and gives it a share once its own offer brings atoms" do
    idle = view(status: :idle)
    {parked, effects} = handle({idle, %State{seq: 1, current: 1}}, {:help_offer, offer(2)})

    assert [%HelpOffer{origin: 2}] = parked.parked
    assert effects == []

    # Our own offer is answered with 6 atoms: they are queued first, and the
    # parked offers are answered once they are.
    atoms = [10, 11, 12, 13, 14, 15]

    assert {state, [{:queue, ^atoms}, {:continue, answer}]} =
             handle({idle, parked}, {:handover, 0, atoms})

    assert state.parked == []

    # Two atoms went to the grandchild's pipe: four queued, five it could
    # give. The parked offerer (as fast as us) gets two, as much as the
    # third helper we plan for.
    busy = view(queued: 4, remaining: 5, in_flight: 1, last_share: 1.0, remaining_us: 10_000)

    assert {_, [{:give, _, 2, 2}, {:event, :give, 2}, {:stat, :offers_consumed}]} =
             handle({busy, state}, answer)
  end

  test "parked offers it cannot serve go straight to the sibling that just gave" do
    idle = view(status: :idle)
    {parked, []} = handle({idle, %State{seq: 1, current: 1}}, {:help_offer, offer(2)})
    {state, [{:queue, [10]}, {:continue, answer}]} = handle({idle, parked}, {:handover, 0, [10]})

    # One atom: it went to the grandchild's pipe, nothing to spare.
    {_, effects} = handle({view(in_flight: 1, remaining_us: 10_000), state}, answer)
    me = self()
    assert [{:help_offer, %HelpOffer{origin: 2, via: ^me}}] = offers_to(effects, {:sibling, 0})
    assert {:stat, :offers_passed} in effects
  end

  test "when its own offer comes back, a child is finished and sends parked offers home" do
    idle = view(status: :idle)
    {state, []} = handle({idle, %State{seq: 1, current: 1}}, {:help_offer, offer(2)})
    {state, []} = handle({idle, state}, {:help_offer, offer(3)})

    {_, effects} = handle({idle, state}, {:help_offer, offer(1)})
    assert :finished in effects

    assert [{:help_offer, %HelpOffer{origin: 2}}, {:help_offer, %HelpOffer{origin: 3}}] =
             offers_to(effects, self())

    assert Enum.count(effects, &(&1 == {:stat, :offers_passed})) == 2
  end

  test "two idle children never hold each other's offers: a wrapped offer is passed, not parked" do
    # Child 0's left is 1, child 1's left is 0. Both go idle, with their own
    # offer out; child 0 has traced nothing yet.
    c0 = view(index: 0, left_index: 1, status: :idle, rate: nil, mean_atom_us: nil)
    c1 = view(index: 1, left_index: 0, status: :idle)

    {s0, e0} = Ring.idle(c0, %State{})
    assert [{:help_offer, %HelpOffer{origin: 0, wrapped: true} = from0}] = offers_to(e0, self())
    {s1, e1} = Ring.idle(c1, %State{})
    assert [{:help_offer, %HelpOffer{origin: 1, wrapped: false} = from1}] = offers_to(e1, self())

    # Child 1 passes child 0's offer (it went past the end of the ring)...
    {s1, passed} = handle({c1, s1}, {:help_offer, from0})
    assert s1.parked == []
    assert [{:help_offer, %HelpOffer{origin: 0, wrapped: true}}] = offers_to(passed, self())

    # ...and child 0 parks child 1's: one of the two offers always walks on.
    {s0, []} = handle({c0, s0}, {:help_offer, from1})
    assert [%HelpOffer{origin: 1}] = s0.parked
  end

  # Tracing its last atom, just started: 2 atoms traced in `busy_us` (no
  # work counted: no rate yet).
  defp on_last_atom(busy_us \\ 20_000) do
    mean = div(busy_us, 2)
    view(in_flight: 1, rate: nil, mean_atom_us: mean, remaining_us: mean)
  end

  # An offer from a sibling that needs 30 ms per atom, 16 hops from home.
  defp far_offer, do: %{offer(2) | hops: 16, atom_us: 30_000}

  test "an offer that walked far waits at a child about to run out, and leaves with its offer" do
    {held, effects} = handle({on_last_atom(), %State{}}, {:help_offer, far_offer()})
    assert effects == []
    assert [%HelpOffer{origin: 2, held: true}] = held.held

    # Out of atoms: its own offer and the held one go left in one message.
    {out, effects} = Ring.idle(%{on_last_atom() | status: :idle, in_flight: 0}, held)

    assert [{_, {:help_offers, [%HelpOffer{origin: 1}, %HelpOffer{origin: 2, hops: 17}]}}] =
             sends(effects)

    assert out.held == []
  end

  test "an offer does not wait twice, nor for a child far from done, nor before it walked far" do
    far = far_offer()

    # Far from done: its last atom has a second left, far more than half of
    # the offerer's 30 ms.
    cases = [
      {on_last_atom(), %{far | held: true}},
      {on_last_atom(2_000_000), far},
      {on_last_atom(), %{far | hops: 15}}
    ]

    for {view, o} <- cases do
      {passed, effects} = handle({view, %State{}}, {:help_offer, o})
      assert passed.held == []
      assert [{:help_offer, %HelpOffer{origin: 2}}] = offers_to(effects, self())
    end
  end

  test "a finished child passes offers on and asks the sender to skip it" do
    sender = spawn(fn -> :ok end)
    finished = view(status: :finished)
    {_, effects} = handle({finished, %State{}}, {:help_offer, offer(2, 1, sender)})

    me = self()
    assert [{:ring_skip, ^me, ^me, 0}] = offers_to(effects, sender)
    # The offer goes on, and names us as its last sender.
    assert [{:help_offer, %HelpOffer{origin: 2, via: ^me}}] = offers_to(effects, me)
    assert Enum.count(effects, &(&1 == {:stat, :offers_passed})) == 1
  end

  test "a finished child that may get atoms of a frame to come is not skipped" do
    sender = spawn(fn -> :ok end)
    finished = view(status: :finished, more_frames: true)
    {_, effects} = handle({finished, %State{}}, {:help_offer, offer(2, 1, sender)})
    assert offers_to(effects, sender) == []
  end

  test "a sender adopts the skipped child's left only if that child is still its left" do
    gone = spawn(fn -> :ok end)
    next = spawn(fn -> :ok end)
    c = view(left: gone, left_index: 2)

    assert {_, [{:left, ^next, 3}]} = handle({c, %State{}}, {:ring_skip, gone, next, 3})
    assert {_, []} = handle({c, %State{}}, {:ring_skip, self(), next, 3})
    # Never to a child known to be dead.
    assert {_, []} = handle({%{c | dead: [3]}, %State{}}, {:ring_skip, gone, next, 3})
  end

  test "the atom waiting in the grandchild's pipe is the one a child can give" do
    # Atoms 5 (being traced) and 6 (waiting) in the pipe, none queued: the
    # child can give one, which `{:give, ...}` takes from the pipe.
    busy = view(in_flight: 1, remaining: 1, last_share: 1.0, remaining_us: 10_000)
    assert {_, [{:give, _, 2, 1} | _]} = handle({busy, %State{}}, {:help_offer, offer(2)})
  end

  test "adaptive atoms: an offer from a much faster sibling cuts the atom being traced in parts" do
    # Atom 5 in 8 parts, 3 of them started: 5 parts left to cut.
    busy = view(in_flight: 1, cuttable: 5, remaining_us: 10_000)

    # 4x faster than us: of the 5 parts not started we keep 1 (a fifth), and
    # the other 4 (half the atom) go to the offerer.
    assert {_, [{:cut, _, 2, keep}, {:event, :give, 2}, {:stat, :offers_consumed}]} =
             handle({busy, %State{}}, {:help_offer, %{offer(2) | rate: 4.0}})

    assert_in_delta keep, 0.2, 1.0e-9

    # An offer from a sibling as fast as we are does not cut: it is passed.
    {_, effects} = handle({busy, %State{}}, {:help_offer, offer(2)})
    refute Enum.any?(effects, &match?({:cut, _, _, _}, &1))
    assert [{:help_offer, %HelpOffer{origin: 2}}] = offers_to(effects, self())

    # Nor does any offer where atoms are kept whole.
    {_, effects} =
      handle(
        {%{busy | options: options(split: false)}, %State{}},
        {:help_offer, %{offer(2) | rate: 4.0}}
      )

    refute Enum.any?(effects, &match?({:cut, _, _, _}, &1))
  end

  test "adaptive atoms: a child traces its atoms in parts once it has heard of a faster sibling" do
    view = fn fields -> view(fields) end
    heard = %State{heard: [{4.0, 2, 9}]}
    # 1 work unit per µs, 10 ms per atom, 16 rows: the sibling is 4x faster.
    assert Ring.parts(view.(next_rows: 16.0), heard) == 4
    # Not shorter than 2 ms, nor than 4 rows; a power of two.
    assert Ring.parts(view.(next_rows: 16.0, mean_atom_us: 6_000), heard) == 2
    assert Ring.parts(view.(next_rows: 12.0), heard) == 2
    assert Ring.parts(view.(next_rows: 16.0), %State{heard: [{64.0, 2, 9}]}) == 4

    assert Ring.parts(view.(next_rows: 64.0, mean_atom_us: 20_000), %State{heard: [{64.0, 2, 9}]}) ==
             8

    # Before the first atom is back: 4 parts (of at least 4 rows).
    assert Ring.parts(view.(next_rows: 16.0, mean_atom_us: nil), %State{}) == 4
    assert Ring.parts(view.(next_rows: 8.0, mean_atom_us: nil), %State{}) == 2
    # Whole: nobody faster heard of, or whole atoms asked for.
    assert Ring.parts(view.(next_rows: 16.0), %State{}) == 1
    assert Ring.parts(view.(next_rows: 16.0), %State{heard: [{1.5, 2, 9}]}) == 1
    assert Ring.parts(view.(next_rows: 16.0, options: [split: false]), heard) == 1
  end

  test "offers carry on what the children they pass have heard of the fastest siblings" do
    busy = view(in_flight: 1, remaining_us: 10_000)
    state = %State{heard: [{5.0, 3, 7}, {0.5, 0, 2}]}

    {passed, effects} =
      handle({busy, state}, {:help_offer, %{offer(2) | heard: [{2.0, 1, 1}, {1.0, 2, 4}]}})

    # The offer says child 1 (us) does 2.0 as of its first atom; our own rate
    # after 4 atoms, 1.0, is newer and goes on instead.
    heard = [{5.0, 3, 7}, {1.0, 2, 4}, {1.0, 1, 4}]
    assert [{:help_offer, %HelpOffer{origin: 2, heard: ^heard}}] = offers_to(effects, self())
    assert passed.heard == heard

    # Our own offer tells the same, and so do the offers held with it.
    held = Map.put(passed, :held, [%{offer(3) | heard: []}])
    {_, effects} = Ring.idle(view(status: :idle), held)

    assert [
             {:help_offers,
              [
                %HelpOffer{origin: 1, rate: 1.0, heard: ^heard},
                %HelpOffer{origin: 3, heard: ^heard}
              ]}
           ] = offers_to(effects, self())
  end

  test "a dead sibling's rate is no longer told" do
    {_, effects} =
      Ring.idle(view(status: :idle, dead: [3]), %State{heard: [{5.0, 3, 7}, {2.0, 0, 2}]})

    assert [{:help_offer, %HelpOffer{origin: 1, heard: [{2.0, 0, 2}, {1.0, 1, 4}]}}] =
             offers_to(effects, self())
  end

  test "a dead sibling is never counted on as the third helper" do
    heard = %State{heard: [{50.0, 3, 9}]}
    slow = %{offer(2) | rate: 0.5}
    # Six atoms queued behind the one being traced.
    busy = view(in_flight: 1, queued: 6, remaining: 6, last_share: 1.0, remaining_us: 10_000)

    # Child 3, fifty times faster than us, would take all six atoms we could
    # give: the slow offer is passed on.
    {_, effects} = handle({busy, heard}, {:help_offer, slow})
    assert [{:help_offer, %HelpOffer{origin: 2}}] = offers_to(effects, self())

    # Dead, it is forgotten; a third helper as fast as us leaves the offerer one.
    {gave, effects} = handle({%{busy | dead: [3]}, heard}, {:help_offer, slow})
    assert [{:give, _, 2, 1} | _] = effects
    assert gave.heard == [{1.0, 1, 4}]
  end

  test "a working child with nothing to spare passes the offer to its left" do
    {_, effects} =
      handle({view(in_flight: 1, remaining_us: 10_000), %State{}}, {:help_offer, offer(2)})

    assert [{:help_offer, %HelpOffer{origin: 2}}] = offers_to(effects, self())
  end

  test "an offer whose origin has died goes no further" do
    {_, effects} = handle({view(in_flight: 1, dead: [2]), %State{}}, {:help_offer, offer(2)})
    assert effects == []
  end

  describe "aiming" do
    # A child that aims (`aim: true`), at job time 0.
    defp aiming(fields), do: view([options: [aim: true]] ++ fields)

    test "an idle child sends its offer straight to the sibling expected to end last" do
      # Sibling 3 said, just now, that it holds 8 queued atoms and should end
      # in a second; sibling 2 ends sooner. Our left sibling is 0.
      loads = [{3, 1_000_000, 0, 8}, {2, 500_000, 0, 8}]
      {_, effects} = Ring.idle(aiming(status: :idle), %State{loads: loads})

      assert [{{:sibling, 3}, {:help_offer, %HelpOffer{origin: 1, aimed: 3} = o}}] =
               sends(effects)

      # It carries what we know: sibling 3 first, and our own load among them.
      assert [{3, 1_000_000, 0, 8} | _] = o.loads
      assert Enum.any?(o.loads, &(elem(&1, 0) == 1))
      refute :finished in effects
    end

    test "with nobody expected to have atoms queued, the offer goes to the left sibling" do
      # Sibling 3 ends late, but has started its last queued atom since it said so.
      loads = [{3, 1_000_000, -900_000, 1}]
      {_, effects} = Ring.idle(aiming(status: :idle), %State{loads: loads})
      assert [{:help_offer, %HelpOffer{origin: 1, aimed: nil}}] = offers_to(effects, self())
    end

    test "without aiming, offers go left and carry no loads" do
      {_, effects} = Ring.idle(view(status: :idle), %State{loads: [{3, 1_000_000, 0, 8}]})

      assert [{:help_offer, %HelpOffer{origin: 1, aimed: nil, loads: []}}] =
               offers_to(effects, self())
    end

    test "an aimed offer that finds nothing walks the ring from its origin's left sibling" do
      target_left = spawn(fn -> :ok end)
      origin_left = spawn(fn -> :ok end)
      # Tracing its last atom: nothing to give.
      target = aiming(index: 3, left: target_left, left_index: 2, in_flight: 1)
      aimed = %{offer(1) | aimed: 3, home_left: {origin_left, 0}, wrapped: true, hops: 1}
      {_, effects} = handle({target, %State{}}, {:help_offer, aimed})

      # As if child 1 had sent it to child 0 itself, with our load first.
      me = self()

      assert [{^origin_left, {:help_offer, %HelpOffer{} = o}}] = sends(effects)
      assert %{origin: 1, aimed: nil, hops: 1, wrapped: false, via: ^me} = o
      assert [{3, _, _, 0} | _] = o.loads
    end

    test "a miss goes back to its origin if the origin's left sibling is dead" do
      target = aiming(index: 3, left_index: 2, in_flight: 1, dead: [0])
      gone = spawn(fn -> :ok end)

      {_, effects} =
        handle({target, %State{}}, {:help_offer, %{offer(1) | aimed: 3, home_left: {gone, 0}}})

      assert [{:help_offer, %HelpOffer{origin: 1, aimed: 3, loads: [{3, _, _, 0} | _]}}] =
               offers_to(effects, self())
    end

    test "an aimed offer that comes home is followed by one that walks the ring" do
      home = aiming(status: :idle)
      back = %{offer(1) | aimed: 3, loads: [{3, 100, 50, 0}]}
      {walking, effects} = handle({home, %State{seq: 1, current: 1}}, {:help_offer, back})

      assert [{:help_offer, %HelpOffer{origin: 1, seq: 2, aimed: nil}}] =
               offers_to(effects, self())

      refute :finished in effects
      # Sibling 3 has nothing to give, and we know it now.
      assert {3, 100, 50, 0} in walking.loads
    end

    test "a giver tells the offerer its load, just lowered, in the hand-over" do
      busy = aiming(in_flight: 1, queued: 6, remaining: 6, last_share: 1.0, remaining_us: 10_000)
      assert {_, [{:give, _, 2, n} | _]} = handle({busy, %State{}}, {:help_offer, offer(2)})
      assert n > 0

      # What the hand-over carries, from the view once the atoms have left.
      after_give = %{busy | queued: 6 - n, remaining: 6 - n}
      {[{1, _end, _at, queued} | _], _} = Ring.handover_news(after_give, %State{})
      assert queued == 6 - n

      # Without aiming, nothing.
      assert {nil, %State{}} = Ring.handover_news(view(), %State{})
    end
  end

  describe "the parent's side of aiming" do
    alias RingTracer.Strategy.ParentView

    defp parent_view(kernel) do
      spec = %{id: make_ref(), layout: RingTracer.Layout.new(8, 1, 2, 2), kernel: {kernel, []}}
      %ParentView{spec: spec, pid: self(), children: %{0 => self(), 1 => self()}}
    end

    test "the work preview is a helper the parent runs: an effect, as data" do
      view = parent_view(RingTracer.Kernel.Native)
      id = view.spec.id
      {board, effects} = Ring.parent_start(view, options(aim: true))

      assert [{:helper, {:atom_work, ^id} = tag, {RingTracer.Kernel.Native, :atom_work, [_, []]}}] =
               effects

      # The board leaves once the preview is back and every child sent an atom.
      {board, []} = Ring.parent_info({tag, {:ok, {1, 1, 1, 1}}}, view, board)
      {board, []} = Ring.parent_atom_done(view, board, 0)
      {_, effects} = Ring.parent_atom_done(%{view | traced_by: %{0 => 0, 2 => 1}}, board, 1)
      assert [{:send, _, :control, {:loads, _}} | _] = effects
    end

    test "no preview without aiming, or from a kernel that cannot make one" do
      assert {nil, []} = Ring.parent_start(parent_view(RingTracer.Kernel.Native), options([]))

      # (`RingTracer.Kernel`'s `atom_work/2` is optional; this module has none.)
      assert {%{board: false}, []} =
               Ring.parent_start(parent_view(__MODULE__), options(aim: true))
    end
  end

  test "adaptive atoms: children of unequal speeds trace pieces that tile the image; split: false (the default) keeps atoms whole" do
    # Eight atoms a child, 10 ms each at full speed: the job lasts long
    # enough that hand-overs come after both sides have measured a rate, even
    # when the schedulers are busy with other work.
    job = [children: 8, atoms: 8, speeds: Enum.to_list(1..8), costs: 10_000]
    n = job[:children] * job[:atoms]
    {:ok, r} = RingTracer.simulate([strategy: {:ring, split: true}] ++ job)
    ids = Enum.map(r.atoms, & &1.atom)
    layout = RingTracer.Layout.new(n, 1, job[:children], job[:atoms])
    assert Enum.any?(ids, &is_tuple/1)
    assert ids == Enum.uniq(ids)
    assert RingTracer.Job.Coverage.tiles?(layout, ids)
    assert length(ids) == n + Enum.sum(Enum.map(r.children, & &1.splits))
    assert r.messages.result.count == length(ids)

    for strategy <- [{:ring, split: false}, :ring] do
      {:ok, fixed} = RingTracer.simulate([strategy: strategy] ++ job)
      assert Enum.sort(Enum.map(fixed.atoms, & &1.atom)) == Enum.to_list(0..(n - 1))
      assert Enum.all?(fixed.children, &(&1.splits == 0))
    end
  end
end
