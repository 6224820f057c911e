defmodule RingTracer.SceneCacheTest do
  use ExUnit.Case, async: false

  import RingTracer.Test.Wait

  alias RingTracer.{SceneCache, TestScenes}

  setup do
    on_exit(fn -> SceneCache.set_max_bytes(256 * 1024 * 1024) end)
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
end
