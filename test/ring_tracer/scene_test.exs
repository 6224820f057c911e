defmodule RingTracer.SceneTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Scene

  alias RingTracer.{Scene, TestScenes}

  test "the source carries bytes and a content hash, and parses the same on this node" do
    scene = Scene.load!(TestScenes.path("balls_s1.nff"))
    assert scene.source.bytes == File.read!(TestScenes.path("balls_s1.nff"))
    assert byte_size(scene.source.hash) == 32
    {:ok, again} = Scene.from_source(scene.source)
    assert again.source.hash == scene.source.hash

    assert {again.width, again.height, again.primitives} ==
             {scene.width, scene.height, scene.primitives}
  end

  test "unknown extensions are refused with the file name" do
    assert {:error, %RingTracer.Error{message: m}} = Scene.load("scene.blend")
    assert m =~ "scene.blend"
  end

  test "a truncated polygon names its line" do
    path =
      TestScenes.tmp_scene("trunc.nff", "b 0 0 0\nl 1 1 1\nf 1 0 0 1 0 0 0 1\np 3\n0 0 0\n1 0\n")

    assert {:error, %RingTracer.Error{reason: :invalid_scene, message: m}} = Scene.load(path)
    assert m =~ "trunc.nff:"
  end
end
