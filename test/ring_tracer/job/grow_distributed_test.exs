defmodule RingTracer.Job.GrowDistributedTest do
  @moduledoc """
  An elastic ring over nodes: children that join a running job on a node
  it did not use trace atoms there (the scene shipped to it first), and
  children that leave hand their atoms on; the image is the same.
  """
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 120_000

  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.TestScenes

  @scene "balls_s2.nff"
  @w 64
  @h 48

  setup_all do
    {p1, n1} = Peers.start("grow1")
    on_exit(fn -> Peers.stop(p1) end)
    {:ok, peer: n1, reference: TestScenes.reference(@scene, @w, @h)}
  end

  setup do
    me = self()
    id = "grow-distributed-#{System.unique_integer([:positive])}"

    :ok =
      RingTracer.Telemetry.attach(
        id,
        [:ring_tracer, :atom, :stop],
        fn _, _, md, _ -> send(me, {:atom, md.child, md.node}) end,
        nil
      )

    on_exit(fn -> RingTracer.Telemetry.detach(id) end)
  end

  # Each atom takes 25 ms more than its tracing (the job lasts about 0.8 s
  # on two children): it still runs when the ring has changed, after its
  # first atom, also when other work slows the join down.
  defp opts(more),
    do: [kernel: {RingTracer.Test.FaultyKernel, delay: 25}, width: @w, height: @h] ++ more

  defp await(id) do
    receive do
      {RingTracer, ^id, {:progress, _, _}} -> await(id)
      {RingTracer, ^id, final} -> final
    after
      60_000 -> flunk("the job did not end")
    end
  end

  test "children that join on another node trace atoms there; the image is the same",
       %{peer: peer, reference: reference} do
    {:ok, job} = RingTracer.render_async(TestScenes.path(@scene), opts(children: 2, atoms: 32))

    # The first atom is in: the job runs.
    assert_receive {:atom, _, _}, 10_000
    {:ok, scene} = RingTracer.Scene.load(TestScenes.path(@scene))
    held? = Map.has_key?(:erpc.call(peer, RingTracer.SceneCache, :info, []), scene.source.hash)
    assert {:ok, [2, 3]} = RingTracer.grow(job, peer, 2)
    assert_receive {:atom, child, ^peer} when child in [2, 3], 5_000
    assert {:ok, result} = await(job.id)

    assert result.pixels == reference
    assert result.failures == []
    assert result.nodes[peer].children == 2
    assert result.nodes[peer].traced > 0
    # the scene went to the peer, packed, unless it held it already
    packed =
      scene.source |> RingTracer.Scene.Source.pack() |> RingTracer.Scene.Source.packed_size()

    assert result.nodes[peer].scene_bytes == if(held?, do: 0, else: packed)
  end

  test "the children of a node that leaves hand their atoms on; the image is the same",
       %{peer: peer, reference: reference} do
    {:ok, job} =
      RingTracer.render_async(
        TestScenes.path(@scene),
        opts(nodes: [peer], children: 4, atoms: 16, strategy: :static)
      )

    assert_receive {:atom, _, _}, 10_000
    assert {:ok, leaving} = RingTracer.shrink(job, peer)
    assert leaving != [] and Enum.all?(leaving, &(rem(&1, 2) == 1))
    assert {:ok, result} = await(job.id)

    assert result.pixels == reference
    # Leaving is no failure; what the leavers held was traced here.
    assert result.failures == []
    assert result.redone > 0
    assert length(result.children) == 4
    for i <- leaving, do: assert(Enum.at(result.children, i).failed == nil)
  end
end
