defmodule RingTracer.DistributedTest do
  use ExUnit.Case, async: false
  # `bin/ringtracer test` runs it in a second test VM (docs/testing.md).
  @moduletag :second_vm

  @moduletag :distributed
  @moduletag timeout: 120_000

  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.TestScenes

  @scene "balls_s2.nff"
  @size [width: 96, height: 72]

  setup_all do
    {p1, n1} = Peers.start("w1")
    {p2, n2} = Peers.start("w2")
    on_exit(fn -> Enum.each([p1, p2], &Peers.stop/1) end)
    {:ok, nodes: [n1, n2], reference: TestScenes.reference(@scene, 96, 72)}
  end

  test "a 3-node render is byte-identical to a 1-node render", %{
    nodes: nodes,
    reference: reference
  } do
    {:ok, scene} = RingTracer.Scene.load(TestScenes.path(@scene))
    held = Map.new(nodes, &{&1, held?(&1, scene)})

    {:ok, result} =
      RingTracer.render(TestScenes.path(@scene), [nodes: nodes, children: 6, atoms: 8] ++ @size)

    assert result.pixels == reference
    assert Enum.sort(Map.keys(result.nodes)) == Enum.sort([node() | nodes])
    assert Enum.all?(Map.values(result.nodes), &(&1.children == 2))
    # The scene went packed to each other node that lacked it ...
    packed =
      scene.source |> RingTracer.Scene.Source.pack() |> RingTracer.Scene.Source.packed_size()

    assert packed > 0

    for n <- nodes do
      assert result.nodes[n].scene_bytes == if(held[n], do: 0, else: packed)
      assert held?(n, scene)
    end

    assert Enum.sort(RingTracer.Cluster.members()) |> Enum.count() >= 3

    # ... and not again to nodes that hold it: by its hash only.
    {:ok, again} =
      RingTracer.render(TestScenes.path(@scene), [nodes: nodes, children: 6, atoms: 8] ++ @size)

    assert again.pixels == reference
    for n <- nodes, do: assert(again.nodes[n].scene_bytes == 0)
  end

  test "children per node, and the local node left out", %{nodes: nodes, reference: reference} do
    {:ok, result} =
      RingTracer.render(
        TestScenes.path(@scene),
        [nodes: nodes, local: false, children_per_node: 3, atoms: 4] ++ @size
      )

    assert result.pixels == reference
    assert Enum.sort(Map.keys(result.nodes)) == Enum.sort(nodes)
    assert length(result.children) == 6
  end

  for seed <- 1..3 do
    test "killing a remote child mid-render still gives the identical image (seed #{seed})", %{
      nodes: nodes,
      reference: reference
    } do
      :rand.seed(:exsss, {unquote(seed), 1, 1})
      [n1 | _] = nodes
      ref = make_ref()

      # The first atom traced on n1 never comes back, so the child holding
      # it (the victim) cannot finish, and the job cannot end, before the
      # kill, however late a busy machine lets this test act; the kill comes
      # after a random number of the other children's atoms.
      {:ok, job} =
        RingTracer.render_async(
          TestScenes.path(@scene),
          [
            nodes: nodes,
            children: 6,
            atoms: 10,
            speeds: [20],
            kernel: {RingTracer.Test.FaultyKernel, block_first: {n1, self(), ref}}
          ] ++ @size
        )

      id = job.id
      assert_receive {:blocked, ^ref, grandchild}, 30_000
      victim = RingTracer.Test.FaultyKernel.child_of(grandchild)
      at = Enum.random(2..30)
      assert_receive {RingTracer, ^id, {:progress, done, _}} when done >= at, 30_000
      Process.exit(victim, :kill)
      assert_receive {RingTracer, ^id, {:ok, result}}, 60_000

      assert result.pixels == reference
      assert length(result.failures) == 1
    end
  end

  test "losing a whole peer node mid-render still gives the identical image", %{
    reference: reference
  } do
    for seed <- 1..3 do
      :rand.seed(:exsss, {seed, 2, 2})
      {p3, n3} = Peers.start("doomed")
      {p4, n4} = Peers.start("spare")

      # The node must still hold atoms when it goes, or the job may end while
      # :peer.stop is under way on a busy machine and lose no child: its
      # children (1 and 4, dealt round robin over this node, n3 and n4) are
      # a thousand times slower, and are held still before it stops.
      stop = fn peer ->
        RingTracer.Test.Hold.children(n3)
        :peer.stop(peer)
      end

      {:ok, result} = render_then([n3, n4], fn -> p3 end, stop, [20, 1000, 20])
      assert result.pixels == reference
      assert length(result.failures) >= 1
      assert Enum.all?(result.failures, &(&1.reason =~ "noconnection"))
      Peers.stop(p4)
    end
  end

  test "a frozen node is declared dead after the liveness timeout and its atoms traced elsewhere",
       %{reference: reference} do
    with_peer("frozen", fn frozen, os_pid ->
      # The frozen node must still hold atoms when it stops, or the job may
      # end without it: the first atom traced there is held (and with it the
      # child's), however late a busy machine lets the `kill` run. The
      # children are not slowed down, so that once the node is declared
      # dead the others trace its atoms at once (slowed 1000x, they took
      # over 20 s on a loaded machine).
      ref = make_ref()

      {:ok, job} =
        RingTracer.render_async(
          TestScenes.path(@scene),
          [
            nodes: [frozen],
            children: 4,
            atoms: 8,
            liveness: 1_000,
            kernel: {RingTracer.Test.FaultyKernel, block_first: {frozen, self(), ref}}
          ] ++ @size
        )

      id = job.id
      assert_receive {:blocked, ^ref, _}, 10_000
      {_, 0} = System.cmd("kill", ["-STOP", os_pid])
      t0 = System.monotonic_time(:millisecond)
      assert_receive {RingTracer, ^id, {:ok, result}}, 30_000
      assert result.pixels == reference
      assert Enum.any?(result.failures, &(&1.reason =~ "noconnection"))
      # Declared dead after about a second, not after distribution's minute.
      assert System.monotonic_time(:millisecond) - t0 < 20_000
    end)
  end

  test "a node that freezes while the job starts fails it after the liveness timeout" do
    with_peer("frozen_at_start", fn frozen, os_pid ->
      t0 = System.monotonic_time(:millisecond)

      assert {:error, %RingTracer.Error{message: message}} =
               RingTracer.render(
                 TestScenes.path(@scene),
                 [
                   nodes: [frozen],
                   children: 4,
                   atoms: 8,
                   liveness: 1_000,
                   kernel: {RingTracer.Test.FaultyKernel, freeze: {frozen, os_pid}}
                 ] ++ @size
               )

      assert message =~ "lost the connection to node #{frozen}"
      # The liveness watch's second, not the minute a scene may take to parse there.
      assert System.monotonic_time(:millisecond) - t0 < 20_000
    end)
  end

  test "a frozen node is a clear error before any work starts" do
    with_peer("frozen_before", fn frozen, os_pid ->
      {_, 0} = System.cmd("kill", ["-STOP", os_pid])

      assert {:error, %RingTracer.Error{reason: :node_unavailable, message: message}} =
               RingTracer.render(TestScenes.path(@scene), nodes: [frozen])

      # the node's first answer is due within 5 s, plus 2 ms a child it starts
      assert message =~ ~r/node #{frozen} did not answer within 50\d\d ms/
    end)
  end

  test "an unreachable node is a clear error before any work starts" do
    assert {:error, %RingTracer.Error{reason: :node_unavailable, message: message}} =
             RingTracer.render(TestScenes.path(@scene), nodes: [:nobody@nowhere])

    assert message =~ "nobody@nowhere"
  end

  test "a node without the project's code is a clear error" do
    {peer, bare} = Peers.start("bare", code: false)

    assert {:error, %RingTracer.Error{reason: :node_unavailable, message: message}} =
             RingTracer.render(TestScenes.path(@scene), nodes: [bare])

    assert message =~ Atom.to_string(bare)
    Peers.stop(peer)
  end

  defp held?(node, scene),
    do: Map.has_key?(:erpc.call(node, RingTracer.SceneCache, :info, []), scene.source.hash)

  # Runs `fun.(node, os_pid)` on a peer of its own, which is then continued
  # (should `fun` have stopped it with SIGSTOP) and stopped, whatever happened.
  defp with_peer(prefix, fun) do
    {peer, node} = Peers.start(prefix)
    os_pid = :erpc.call(node, :os, :getpid, []) |> List.to_string()

    try do
      fun.(node, os_pid)
    after
      System.cmd("kill", ["-CONT", os_pid])
      Peers.stop(peer)
    end
  end

  # Renders on `nodes` (and this node), the children slowed down by
  # `speeds`. At the first atom `pick` chooses a victim; after a random
  # number of atoms (at most half of the 60) `kill` gets it.
  defp render_then(nodes, pick, kill, speeds) do
    {:ok, job} =
      RingTracer.render_async(
        TestScenes.path(@scene),
        [nodes: nodes, children: 6, atoms: 10, speeds: speeds] ++ @size
      )

    await(job.id, Enum.random(2..30), pick, kill, nil)
  end

  defp await(id, at, pick, kill, victim) do
    receive do
      {RingTracer, ^id, {:progress, 1, _}} ->
        await(id, at, pick, kill, pick.())

      {RingTracer, ^id, {:progress, ^at, _}} ->
        kill.(victim)
        await(id, at, pick, kill, victim)

      {RingTracer, ^id, {:progress, _, _}} ->
        await(id, at, pick, kill, victim)

      {RingTracer, ^id, result} ->
        result
    end
  end
end
