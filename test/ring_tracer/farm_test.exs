defmodule RingTracer.FarmTest do
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 180_000

  alias RingTracer.{Farm, Native}
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait
  alias RingTracer.TestScenes

  @size [width: 64, height: 48]

  setup_all do
    Peers.ensure_distributed()
    {p1, n1} = Peers.start("fw1")
    {p2, n2} = Peers.start("fw2")

    on_exit(fn -> Enum.each([p1, p2], &Peers.stop/1) end)
    {:ok, peers: [{p1, n1}, {p2, n2}]}
  end

  setup %{peers: peers} do
    dir = Path.join(System.tmp_dir!(), "rt_farm_#{System.unique_integer([:positive])}")
    {:ok, _} = Farm.start_head(dir: dir)

    # The second worker emulates a machine twice as slow.
    for {{p, n}, speed} <- Enum.zip(peers, [1, 2]),
        do: {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 2, speed: speed]])

    assert Wait.eventually(fn -> length(elem(Farm.workers(node()), 1)) == 2 end, 500)
    {:ok, workers} = Farm.workers(node())
    assert Enum.map(workers, &{&1.slots, &1.speed}) |> Enum.sort() == [{2, 1}, {2, 2}]

    on_exit(fn ->
      for {p, n} <- peers, do: :ok = Peers.call(p, n, Farm, :leave, [])
      Farm.stop_head()
      File.rm_rf!(dir)
    end)

    {:ok, dir: dir}
  end

  test "a still is queued, rendered over the workers and fetched byte-identical" do
    {:ok, id} = Farm.submit(node(), TestScenes.path("balls_s2.nff"), @size ++ [user: "ann"])
    frames = self()

    {:ok, info} =
      Farm.wait(node(), id, on_frame: fn n, bytes -> send(frames, {:got, n, bytes}) && :ok end)

    assert {info.state, info.error, info.done} == {:done, nil, [1]}
    assert_received {:got, 1, png}

    reference = TestScenes.reference("balls_s2.nff", 64, 48)
    {:ok, expected} = RingTracer.Image.png(64, 48, reference)
    assert png == expected
  end

  test "wait takes only an end the head confirms (not one an earlier head's job left here)" do
    # No worker has the tag: the job stays queued.
    {:ok, id} = Farm.submit(node(), TestScenes.path("balls_s2.nff"), @size ++ [tags: ["none"]])
    # What a job of the same id on a head since replaced left in this mailbox.
    send(self(), {RingTracer.Farm, id, {:end, :done, nil}})
    assert {:error, %RingTracer.Error{reason: :timeout}} = Farm.wait(node(), id, timeout: 500)
    :ok = Farm.cancel(node(), id)
    assert {:ok, %{state: :cancelled}} = Farm.wait(node(), id, timeout: 5_000)
  end

  test "a sequence's frames are each the frame rendered alone" do
    {:ok, id} =
      Farm.submit(
        node(),
        TestScenes.path("whitted_orbit.toml"),
        @size ++ [frames: 2..5, format: :exr]
      )

    me = self()
    {:ok, info} = Farm.wait(node(), id, on_frame: fn n, b -> send(me, {:got, n, b}) && :ok end)
    assert info.state == :done and info.done == [2, 3, 4, 5]

    for n <- 2..5 do
      assert_received {:got, ^n, exr}
      dir = Path.join(System.tmp_dir!(), "rt_farm_exr_#{n}_#{System.unique_integer([:positive])}")
      File.mkdir_p!(dir)
      path = Path.join(dir, "f.exr")
      reference = TestScenes.reference("whitted_orbit.toml", 64, 48, frame: n)
      :ok = RingTracer.Image.write(path, 64, 48, reference)
      assert exr == File.read!(path)
      File.rm_rf!(dir)
    end
  end

  test "two users share the workers; cancel stops a job; jobs lists them all" do
    slow = [kernel: {RingTracer.Kernel.Simulated, costs: 20_000}, atoms: 8]

    {:ok, a} =
      Farm.submit(node(), TestScenes.path("whitted_orbit.toml"), @size ++ slow ++ [user: "ann"])

    {:ok, b} =
      Farm.submit(node(), TestScenes.path("whitted_orbit.toml"), @size ++ slow ++ [user: "bob"])

    assert Wait.eventually(
             fn ->
               {:ok, jobs} = Farm.jobs(node())

               Enum.map(jobs, &{&1.id, &1.state, length(&1.workers)})
               |> Enum.filter(&(elem(&1, 0) in [a, b])) ==
                 [{a, :running, 1}, {b, :running, 1}]
             end,
             500
           )

    :ok = Farm.cancel(node(), a)
    {:ok, info} = Farm.status(node(), a)
    assert info.state == :cancelled
    assert {:error, %RingTracer.Error{reason: :farm}} = Farm.cancel(node(), a)
    :ok = Farm.cancel(node(), b)
  end

  test "bad submissions are refused before anything is queued" do
    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             Farm.submit(node(), TestScenes.path("balls_s2.nff"), nodes: [node()])

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             Farm.submit(node(), TestScenes.path("balls_s2.nff"), tags: ["no spaces"])

    assert {:error, %RingTracer.Error{reason: :file}} =
             Farm.submit(node(), "/nonexistent/scene.nff", [])

    assert {:error, %RingTracer.Error{reason: :farm}} = Farm.status(node(), 999_999)

    assert {:error, %RingTracer.Error{reason: :invalid_option}} = Farm.join(node(), speed: 0.5)

    assert {:error, %RingTracer.Error{reason: :farm_unreachable}} =
             Farm.jobs(:nohead@localhost, timeout: 2_000)
  end

  test "Native is loaded on the head" do
    assert is_function(&Native.render_image/3)
  end
end
