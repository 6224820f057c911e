defmodule RingTracer.ProtocolPropertyTest do
  @moduledoc """
  The ring protocol under adversarial schedules: random ring sizes, atoms,
  image sizes, speeds, strategies, layouts (strips or interleaved), aimed
  offers or not, adaptive atoms (pieces, and cuts of atoms being traced in
  parts) or not, message delays (which reorder messages: `RingTracer.Test.DelayedStrategy`
  and `RingTracer.Test.FaultyKernel`), child kills and
  how soon offers may wait at a child (`:hold_after`), against the real
  parent, children and kernel, and children that join the running job
  (`RingTracer.grow/4`) at random points. Every job ends with the single-process
  image, every pixel traced once in the records the parent kept (whole
  atoms or pieces tiling them), no process left behind, and, after kills,
  at most twice the messages of the same job without them (no storms).

  A third property runs sequences (`RingTracer.render_sequence/2`), with
  children that join too: every frame once, each the frame rendered
  alone, across frame boundaries.

  CI runs 1,000 cases (200 missed a hang that 2,000 found; sequences 200); `PROPER_NUMTESTS=5000 mix test
  test/ring_tracer/protocol_property_test.exs --include slow` runs more.
  """
  use ExUnit.Case, async: false
  # `bin/ringtracer test` runs it in a second test VM (docs/testing.md).
  @moduletag :second_vm

  alias RingTracer.TestScenes

  import RingTracer.TestScenes, only: [children: 0]

  @moduletag :slow
  @moduletag timeout: :infinity
  @scene "balls_s1.nff"

  defp gen do
    import :proper_types

    {integer(1, 7), integer(1, 6), integer(1, 20), integer(1, 14), list(integer(1, 3)),
     oneof([:ring, :static, :master, :steal]), integer(0, 4), integer(0, 2),
     integer(0, 1_000_000), integer(1, 3), oneof([:strips, :interleaved]),
     oneof([nil, true, false]), boolean(), integer(0, 2)}
  end

  test "property: every schedule ends with the single-process image and no process left" do
    numtests = String.to_integer(System.get_env("PROPER_NUMTESTS", "1000"))
    references = :ets.new(:references, [:set, :public])
    # Children that joined a job and traced atoms of it, over every case.
    joined = :counters.new(1, [])

    RingTracer.PropErCase.check(
      gen(),
      fn {n, k, w, h, speeds, strategy, chaos, kills, seed, hold_after, layout, aim, split, joins} =
           case_ ->
        if System.get_env("PROPER_VERBOSE"), do: IO.inspect(case_)
        :rand.seed(:exsss, {seed, n, k})
        kills = min(kills, n - 1)

        reference =
          case :ets.lookup(references, {w, h}) do
            [{_, ref}] -> ref
            [] -> tap(TestScenes.reference(@scene, w, h), &:ets.insert(references, {{w, h}, &1}))
          end

        job = [
          children: n,
          atoms: k,
          width: w,
          height: h,
          speeds: speeds,
          # Small rings: let offers wait after 1-3 hops so that holding is
          # exercised (the default, 16, needs a ring of 17 or more); aim nil:
          # the default for the layout (see `RingTracer.Strategy.Ring.Aim`);
          # adaptive atoms: pieces near the end of the job (ring only).
          strategy: strategy(strategy, hold_after: hold_after, aim: aim, split: split),
          layout: layout
        ]

        opts = delayed(job, chaos)

        kill_at = Enum.take_random(1..(n * k), kills)
        # Children join at random points: before the first atom (0) or as
        # an atom arrives.
        join_at = Enum.take_random(0..(n * k), joins)

        # The same job without kills or joins, for the bound on messages.
        clean =
          if kill_at != [] or join_at != [] do
            {:ok, job} = RingTracer.render_async(TestScenes.path(@scene), opts)
            await(job, [], [])
          end

        {:ok, job} = RingTracer.render_async(TestScenes.path(@scene), opts)
        if 0 in join_at, do: join(job, 0)
        result = await(job, kill_at, join_at)

        ok =
          case result do
            {:ok, r} ->
              # One record per atom or piece (the copy the parent kept),
              # tiling every atom exactly, unless a killed child took its
              # records with it.
              ids = Enum.map(r.atoms, & &1.atom)
              layout = RingTracer.Layout.new(w, h, n, k)
              lost_records = Enum.any?(r.children, &(&1.failed != nil))
              :counters.add(joined, 1, Enum.count(r.children, &(&1.index >= n and &1.traced > 0)))

              r.pixels == reference and length(r.failures) <= length(kill_at) and
                length(r.children) <= n + 2 * length(join_at) and
                ids == Enum.uniq(ids) and
                (lost_records or RingTracer.Job.Coverage.tiles?(layout, ids)) and
                (split or not Enum.any?(ids, &is_tuple/1)) and
                no_storm?(r, clean, strategy, n)

            _ ->
              false
          end

        # Stopped processes are reaped asynchronously (5 ms was once too
        # little on a loaded machine): leftovers are what is still there
        # after up to 5 s (500 tries 10 ms apart).
        leftovers = fn -> {children(), DynamicSupervisor.which_children(RingTracer.Jobs)} end
        RingTracer.Test.Wait.eventually(fn -> leftovers.() == {[], []} end, 500)
        left = leftovers.()

        if System.get_env("PROPER_VERBOSE") && not (ok and left == {[], []}) do
          summary =
            case result do
              {:ok, r} ->
                {r.pixels == reference, r.failures, r.redone, byte_size(r.pixels),
                 byte_size(reference), Enum.map(r.children, &{&1.own, &1.traced, &1.received})}

              error ->
                error
            end

          IO.inspect({left, kill_at, summary}, label: "failed case")
        end

        ok and left == {[], []}
      end,
      numtests
    )

    # The property is about joins too: children joined and traced atoms.
    assert :counters.get(joined, 1) > 0
  end

  test "property: cuts of atoms being traced in parts tile the image, with message delays and kills" do
    # Atoms that take real time (the simulated kernel: up to milliseconds each) on
    # children up to 8x apart, so that offers reach slow children mid-atom.
    import :proper_types

    gen =
      {integer(2, 5), integer(4, 12), list(integer(1, 8)), integer(4, 12), integer(0, 3),
       integer(0, 1), integer(0, 1_000_000)}

    cuts = :counters.new(1, [])
    numtests = div(String.to_integer(System.get_env("PROPER_NUMTESTS", "1000")), 20)

    RingTracer.PropErCase.check(
      gen,
      fn {n, k, speeds, ms, chaos, kills, seed} ->
        :rand.seed(:exsss, {seed, n, k})
        # Costs that vary from atom to atom (1 to `ms` milliseconds), so that
        # the share rule's plans miss and offers come while parts are left.
        costs = for _ <- 1..(n * k), do: :rand.uniform(ms * 1000)
        job = [children: n, atoms: k, speeds: speeds, costs: costs]
        # Cuts for any offerer at all (`cut_faster: 0.0`), not only much faster ones.
        inner =
          {RingTracer.Strategy.Ring,
           [split: true, part_us: 0, part_rows: 0, cut_faster: 0.0, aim: n > 2]}

        strategy = {RingTracer.Test.DelayedStrategy, [inner: inner, jitter: chaos]}

        # A kill at a random moment of the job's first half.
        killer =
          spawn(fn ->
            Process.sleep(:rand.uniform(div(k * ms, 2) + 1))

            case {kills, children()} do
              {1, [_ | _] = kids} -> Process.exit(Enum.random(kids), :kill)
              _ -> :ok
            end
          end)

        result = RingTracer.simulate([strategy: strategy] ++ job)
        Process.exit(killer, :kill)

        case result do
          {:ok, r} ->
            ids = Enum.map(r.atoms, & &1.atom)
            :counters.add(cuts, 1, Enum.sum(Enum.map(r.children, &Map.get(&1, :cuts, 0))))
            lost_records = Enum.any?(r.children, &(&1.failed != nil))
            layout = RingTracer.Layout.new(n * k, 1, n, k)

            ids == Enum.uniq(ids) and
              (lost_records or RingTracer.Job.Coverage.tiles?(layout, ids))

          _ ->
            false
        end
      end,
      numtests
    )

    # The property is about cuts: they happened (13 to 20 in 50 cases).
    assert :counters.get(cuts, 1) > 0
  end

  test "property: a sequence gives every frame once, each the frame rendered alone, across frame boundaries" do
    # Sequences of 1 to 4 frames of an animated scene whose objects and
    # camera move, windows of 1 to 3 frames, every strategy, layout and
    # split, with message delays and child kills: each frame comes once,
    # equal to the frame rendered alone, the job ends and leaves nothing.
    import :proper_types

    gen =
      {integer(1, 5), integer(1, 4), integer(1, 12), integer(1, 9), list(integer(1, 48)),
       integer(1, 3), oneof([:ring, :static, :master, :steal]), oneof([:strips, :interleaved]),
       boolean(), integer(0, 3), integer(0, 2), list(integer(1, 3)), integer(0, 1_000_000),
       integer(0, 2)}

    references = :ets.new(:frame_references, [:set, :public])
    scene = "whitted_orbit.toml"
    numtests = div(String.to_integer(System.get_env("PROPER_NUMTESTS", "1000")), 5)

    RingTracer.PropErCase.check(
      gen,
      fn {n, k, w, h, picks, window, strategy, layout, split, chaos, kills, speeds, seed, joins} =
           case_ ->
        if System.get_env("PROPER_VERBOSE"), do: IO.inspect(case_)
        :rand.seed(:exsss, {seed, n, k})
        numbers = picks |> Enum.take(4) |> Enum.uniq() |> Enum.sort()
        numbers = if numbers == [], do: [1], else: numbers
        kills = min(kills, n - 1)

        job = [
          children: n,
          atoms: k,
          width: w,
          height: h,
          speeds: speeds,
          strategy: strategy(strategy, split: split),
          layout: layout
        ]

        opts = delayed(job, chaos)

        total = n * k * length(numbers)
        kill_at = Enum.take_random(1..total, kills)
        join_at = Enum.take_random(0..total, joins)

        {:ok, job} =
          RingTracer.render_sequence(
            TestScenes.path(scene),
            [frames: numbers, window: window] ++ opts
          )

        if 0 in join_at, do: join(job, 0)
        {frames, final} = await_frames(job, kill_at, join_at, [])

        ok =
          match?({:ok, _}, final) and Enum.map(frames, &elem(&1, 0)) |> Enum.sort() == numbers and
            Enum.all?(frames, fn {number, frame} ->
              reference =
                case :ets.lookup(references, {number, w, h}) do
                  [{_, ref}] ->
                    ref

                  [] ->
                    ref = TestScenes.reference(scene, w, h, frame: number)
                    tap(ref, &:ets.insert(references, {{number, w, h}, &1}))
                end

              frame.pixels == reference
            end)

        Process.sleep(5)
        left = {children(), DynamicSupervisor.which_children(RingTracer.Jobs)}

        if System.get_env("PROPER_VERBOSE") && not (ok and left == {[], []}),
          do: IO.inspect({left, kill_at, Enum.map(frames, &elem(&1, 0)), final}, label: "failed")

        ok and left == {[], []}
      end,
      numtests
    )
  end

  # `job`'s options with delays of up to `chaos` ms, which reorder
  # messages: on what the strategy has a child send, and on each atom's
  # result. With adaptive atoms, atoms in parts however short (`part_us`,
  # `part_rows`), so that cuts of the atom being traced happen on these
  # tiny jobs.
  defp delayed(job, chaos) do
    parts = if match?({:ring, _}, job[:strategy]), do: [part_us: 0, part_rows: 0], else: []

    Keyword.merge(job,
      strategy: RingTracer.Test.DelayedStrategy.wrap(job, [jitter: chaos] ++ parts),
      kernel: {RingTracer.Test.FaultyKernel, jitter: chaos}
    )
  end

  # The job's strategy: the ring with its own options (nil: its default),
  # any other by name.
  defp strategy(:ring, options), do: {:ring, Enum.reject(options, &is_nil(elem(&1, 1)))}
  defp strategy(name, _options), do: name

  defp kill_a_child do
    case children() do
      [] -> :ok
      kids -> Process.exit(Enum.random(kids), :kill)
    end
  end

  # One or two children join the running job on this node; a job that has
  # just ended answers :job_ended.
  defp join(job, done) do
    case RingTracer.grow(job, node(), 1 + rem(done, 2)) do
      {:ok, _} -> :ok
      {:error, %RingTracer.Error{reason: :job_ended}} -> :ok
    end
  end

  # The frames of a sequence as they come (a number twice stays twice, for
  # the property to see), killing a child at the atoms counted in `kill_at`
  # and adding children at those in `join_at`.
  defp await_frames(%{id: id} = job, kill_at, join_at, frames) do
    receive do
      {RingTracer, ^id, {:frame, n, frame}} ->
        await_frames(job, kill_at, join_at, [{n, frame} | frames])

      {RingTracer, ^id, {:progress, done, _}} ->
        if done in kill_at, do: kill_a_child()
        if done in join_at, do: join(job, done)

        await_frames(job, kill_at, join_at, frames)

      {RingTracer, ^id, final} ->
        {frames, final}
    after
      10_000 ->
        for pid <- children(), do: Process.exit(pid, :kill)
        {frames, {:error, :hung}}
    end
  end

  # After kills, at most twice the messages of the same job without them
  # (the job's atoms are the same, so this is messages per atom). What a
  # killed child sent is not counted: its report dies with it. Steal's own
  # end of a job is every idle child asking every sibling once (request and
  # reply) before it is finished; a clean run cut short by its last atom
  # may send a few of those N(N - 1) pairs and one lengthened by a kill all
  # of them, so for steal one such round is allowed on top. The ring's
  # offers likewise: offers that walked on together in one message in the
  # clean run may walk one by one in the other (timing alone decides), and
  # the last offer of each of the N children may walk N hops: N * N on top.
  defp no_storm?(_result, nil, _strategy, _n), do: true

  #
  # Children that joined (`grow/4`) count in N, and each costs the parent's
  # news to every child and its own first offers or steals: 4 N more.
  defp no_storm?(result, {:ok, clean}, strategy, n) do
    total = fn r -> r.messages |> Map.values() |> Enum.map(& &1.count) |> Enum.sum() end
    all = length(result.children)
    joined = all - n

    sweeps =
      case strategy do
        :steal -> 2 * all * (all - 1)
        :ring -> all * all
        _ -> 0
      end

    ok = total.(result) <= 2 * total.(clean) + sweeps + 4 * all * joined

    if System.get_env("PROPER_VERBOSE") && not ok,
      do: IO.inspect({result.messages, clean.messages}, label: "storm")

    ok
  end

  defp no_storm?(_result, _clean, _strategy, _n), do: false

  defp await(%{id: id} = job, kill_at, join_at) do
    receive do
      {RingTracer, ^id, {:progress, done, _}} ->
        if done in kill_at, do: kill_a_child()
        if done in join_at, do: join(job, done)

        await(job, kill_at, join_at)

      {RingTracer, ^id, result} ->
        result
    after
      # "The job ends" is part of the property: a job silent this long hangs.
      10_000 ->
        states =
          for pid <- children() do
            st = :sys.get_state(pid)
            {st.index, st.status, st.queue, st.in_flight, st.early}
          end

        IO.inspect(states, label: "hung job's children")
        for pid <- children(), do: Process.exit(pid, :kill)
        {:error, :hung}
    end
  end
end
