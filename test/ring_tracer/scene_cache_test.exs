defmodule RingTracer.SceneCacheTest do
  use ExUnit.Case, async: false

  import RingTracer.Test.Wait

  alias RingTracer.{SceneCache, TestScenes}

  setup do
    on_exit(fn ->
      SceneCache.set_max_bytes(256 * 1024 * 1024)
      SceneCache.set_max_frames(8)
    end)
  end

  # Distinct scenes (a comment changes the hash), the same picture.
  defp scenes(n) do
    base = File.read!(TestScenes.path("tetra_s1.nff"))
    for i <- 1..n, do: TestScenes.tmp_scene("t#{i}.nff", "# copy #{i}\n" <> base)
  end

  test "concurrent jobs of more distinct scenes than the cache holds all succeed" do
    # A budget of one byte: every scene is evicted as soon as nobody pins it.
    :ok = SceneCache.set_max_bytes(1)
    reference = TestScenes.reference("tetra_s1.nff", 32, 24)

    jobs =
      for path <- scenes(12) do
        {:ok, job} = RingTracer.render_async(path, children: 4, atoms: 4, width: 32, height: 24)
        job.id
      end

    for id <- jobs do
      assert_receive {RingTracer, ^id, {:ok, result}}, 30_000
      assert result.pixels == reference
    end
  end

  test "a pin lasts as long as its owner, and unpinned scenes are evicted by bytes" do
    [path] = scenes(1)
    {:ok, scene} = RingTracer.Scene.load(path)
    :ok = SceneCache.set_max_bytes(1)
    owner = spawn(fn -> receive do: (:stop -> :ok) end)
    :ok = SceneCache.pin(scene.source, owner)
    assert %{pins: 1} = SceneCache.info()[scene.source.hash]

    ref = Process.monitor(owner)
    send(owner, :stop)
    assert_receive {:DOWN, ^ref, _, _, _}
    # The cache's own monitor fires too; its DOWN may come after our call.
    assert eventually(fn -> not Map.has_key?(SceneCache.info(), scene.source.hash) end)
  end

  # An animated scene (its objects move) of a hash no other test uses.
  defp orbit do
    base = File.read!(TestScenes.path("whitted_orbit.toml"))
    tag = Base.url_encode64(:crypto.strong_rand_bytes(6))
    {:ok, scene} = RingTracer.Scene.load(TestScenes.tmp_scene("orbit.toml", "# #{tag}\n" <> base))
    scene
  end

  defp pixels(ref) do
    native = RingTracer.Settings.to_native(%RingTracer.Settings{width: 16, height: 12})
    {:ok, {pixels, _rays}} = RingTracer.Native.render_image(ref, native, 1)
    pixels
  end

  test "children fetching a frame at once get one frame, built once, and it is the frame's scene" do
    scene = orbit()

    refs =
      1..12
      |> Enum.map(fn _ -> Task.async(fn -> SceneCache.fetch_frame(scene.source, 5) end) end)
      |> Enum.map(&Task.await(&1, 30_000))

    assert [{:ok, ref}] = Enum.uniq(refs)
    assert %{frames: [5]} = SceneCache.info()[scene.source.hash]
    assert {:ok, ^ref} = SceneCache.fetch_frame(scene.source, 5)

    {:ok, built} = RingTracer.Native.scene_frame(scene.ref, 5)
    assert pixels(ref) == pixels(built)
    assert pixels(ref) != pixels(scene.ref)

    assert SceneCache.fetch_frame(scene.source, 0) ==
             {:ok, SceneCache.fetch(scene.source) |> elem(1) |> Map.fetch!(:ref)}
  end

  test "a scene's frames are bounded, least recently fetched out, and a dropped one lives on while held" do
    scene = orbit()
    :ok = SceneCache.set_max_frames(2)
    {:ok, first} = SceneCache.fetch_frame(scene.source, 1)
    for f <- [2, 3], do: {:ok, _} = SceneCache.fetch_frame(scene.source, f)
    assert %{frames: [2, 3]} = SceneCache.info()[scene.source.hash]

    # fetching 2 again makes 3 the least recently fetched
    {:ok, _} = SceneCache.fetch_frame(scene.source, 2)
    {:ok, _} = SceneCache.fetch_frame(scene.source, 4)
    assert %{frames: [2, 4]} = SceneCache.info()[scene.source.hash]

    # frame 1 was dropped, but whoever holds it still traces it
    {:ok, again} = SceneCache.fetch_frame(scene.source, 1)
    assert again != first
    assert pixels(first) == pixels(again)

    :ok = SceneCache.set_max_frames(0)
    assert %{frames: []} = SceneCache.info()[scene.source.hash]
    assert {:ok, _} = SceneCache.fetch_frame(scene.source, 3)
    assert %{frames: []} = SceneCache.info()[scene.source.hash]
  end

  test "a scene's frames go when the scene is evicted" do
    scene = orbit()
    hash = scene.source.hash
    owner = spawn(fn -> receive do: (:stop -> :ok) end)
    :ok = SceneCache.pin(scene.source, owner)
    for f <- [1, 2], do: {:ok, _} = SceneCache.fetch_frame(scene.source, f)
    :ok = SceneCache.set_max_bytes(1)
    assert %{frames: [1, 2], pins: 1} = SceneCache.info()[hash]

    send(owner, :stop)
    assert eventually(fn -> not Map.has_key?(SceneCache.info(), hash) end)
    assert :ets.lookup(SceneCache, {hash, 1}) == []
    assert :ets.lookup(SceneCache, {hash, 2}) == []
  end

  test "a frame past the scene's last, or not a frame, is an error and the cache lives on" do
    scene = orbit()
    cache = Process.whereis(SceneCache)

    assert {:error, %RingTracer.Error{message: message}} =
             SceneCache.fetch_frame(scene.source, 48)

    assert message =~ "48 frame(s)"
    assert message =~ "no frame 48"

    assert {:error, %RingTracer.Error{}} = SceneCache.fetch_frame(scene.source, -1)
    assert {:error, %RingTracer.Error{}} = SceneCache.fetch_frame(scene.source, 1.5)
    assert {:error, %RingTracer.Error{}} = SceneCache.fetch_frame(scene.source, 2 ** 40)

    {:ok, still} = RingTracer.Scene.load(TestScenes.path("tetra_s1.nff"))
    assert {:error, %RingTracer.Error{}} = SceneCache.fetch_frame(still.source, 1)
    assert {:ok, _} = SceneCache.fetch_frame(still.source, 0)

    assert Process.whereis(SceneCache) == cache
    assert %{frames: []} = SceneCache.info()[scene.source.hash]
  end
end
