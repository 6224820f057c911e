defmodule RingTracer.Farm.ElasticTest do
  @moduledoc """
  A worker that joins a farm while a job runs gets children in that job's
  ring within a second (`RingTracer.grow/4` from the job's runner), one
  that leaves hands its work on (`RingTracer.shrink/3`), and every frame is
  still the frame rendered alone.
  """
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 180_000

  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait
  alias RingTracer.TestScenes

  @scene "whitted_orbit.toml"
  @w 64
  @h 48
  @frames 1..24

  setup_all do
    Peers.ensure_distributed()
    {p1, n1} = Peers.start("ew1")
    {p2, n2} = Peers.start("ew2")
    on_exit(fn -> Enum.each([p1, p2], &Peers.stop/1) end)
    {:ok, first: {p1, n1}, second: {p2, n2}}
  end

  setup %{first: {p1, n1}, second: {p2, n2}} do
    dir = Path.join(System.tmp_dir!(), "rt_farm_elastic_#{System.unique_integer([:positive])}")
    {:ok, _} = Farm.start_head(dir: dir)
    me = self()
    id = "farm-elastic-#{System.unique_integer([:positive])}"

    :ok =
      RingTracer.Telemetry.attach(
        id,
        [:ring_tracer, :atom, :stop],
        fn _, _, md, _ ->
          if md.node == n2, do: send(me, {:atom_on_second, System.monotonic_time(:millisecond)})
        end,
        nil
      )

    on_exit(fn ->
      RingTracer.Telemetry.detach(id)
      for {p, n} <- [{p1, n1}, {p2, n2}], do: Peers.call(p, n, Farm, :leave, [])
      Farm.stop_head()
      File.rm_rf!(dir)
    end)

    :ok
  end

  test "a worker that joins mid-job traces atoms of it within a second; the frames are the same",
       %{first: {p1, n1}, second: {p2, n2}} do
    # The first worker emulates a machine six times slower: the job runs
    # for a while on it alone.
    {:ok, _} = Peers.call(p1, n1, Farm, :join, [node(), [slots: 2, speed: 6]])
    assert Wait.eventually(fn -> length(elem(Farm.workers(node()), 1)) == 1 end, 500)

    {:ok, id} =
      Farm.submit(node(), TestScenes.path(@scene), width: @w, height: @h, frames: @frames)

    me = self()

    waiter =
      Task.async(fn ->
        Farm.wait(node(), id, on_frame: fn n, bytes -> send(me, {:got, n, bytes}) && :ok end)
      end)

    # Mid-job: the first frame is in, and more are to come.
    assert_receive {:got, n, bytes}, 30_000
    send(self(), {:got, n, bytes})
    joined_at = System.monotonic_time(:millisecond)
    {:ok, _} = Peers.call(p2, n2, Farm, :join, [node(), [slots: 2]])

    assert_receive {:atom_on_second, first_atom}, 5_000
    assert first_atom - joined_at < 1_000, "join to first atom: #{first_atom - joined_at} ms"

    assert {:ok, info} = Task.await(waiter, 120_000)
    assert info.state == :done and info.done == Enum.to_list(@frames)

    for n <- @frames do
      assert_received {:got, ^n, png}
      reference = TestScenes.reference(@scene, @w, @h, frame: n)
      {:ok, expected} = RingTracer.Image.png(@w, @h, reference)
      assert png == expected, "frame #{n}"
    end
  end

  test "a worker that leaves mid-job hands its work on; the frames are the same",
       %{first: {p1, n1}, second: {p2, n2}} do
    for {p, n} <- [{p1, n1}, {p2, n2}],
        do: {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 2, speed: 4]])

    assert Wait.eventually(fn -> length(elem(Farm.workers(node()), 1)) == 2 end, 500)

    {:ok, id} = Farm.submit(node(), TestScenes.path(@scene), width: @w, height: @h, frames: 1..12)

    me = self()

    waiter =
      Task.async(fn ->
        Farm.wait(node(), id, on_frame: fn n, bytes -> send(me, {:got, n, bytes}) && :ok end)
      end)

    assert_receive {:got, n, bytes}, 30_000
    send(self(), {:got, n, bytes})
    assert_receive {:atom_on_second, _}, 5_000
    me = self()
    handler = "farm-elastic-shrunk-#{System.unique_integer([:positive])}"
    shrunk = fn _, _, md, _ -> send(me, {:shrunk, md.node}) end
    :ok = RingTracer.Telemetry.attach(handler, [:ring_tracer, :job, :shrunk], shrunk, nil)
    on_exit(fn -> RingTracer.Telemetry.detach(handler) end)
    :ok = Peers.call(p2, n2, Farm, :leave, [])
    # The head lets the worker go, and its children leave the ring.
    assert_receive {:shrunk, ^n2}, 5_000

    assert {:ok, info} = Task.await(waiter, 120_000)
    assert info.state == :done and info.done == Enum.to_list(1..12)

    for n <- 1..12 do
      assert_received {:got, ^n, png}
      reference = TestScenes.reference(@scene, @w, @h, frame: n)
      {:ok, expected} = RingTracer.Image.png(@w, @h, reference)
      assert png == expected, "frame #{n}"
    end
  end
end
