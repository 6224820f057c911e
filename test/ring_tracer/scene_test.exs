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

  @view "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 8 8\nl 1 2 3\n"

  test "what renders but maybe not as meant loads, with warnings naming file and line" do
    path = TestScenes.tmp_scene("odd.nff", @view <> "s 0 0 0 0\nf 2 0 0 1 0 1 0 1\ns 0 0 0 1\n")
    assert {:ok, scene} = Scene.load(path)
    assert scene.primitives == 1

    assert [
             %Scene.Warning{file: "odd.nff", line: 8, message: zero},
             %Scene.Warning{file: "odd.nff", line: 9, message: colour}
           ] = scene.warnings

    assert zero == "sphere 's' has radius 0 and is not rendered"
    assert colour =~ "colour 2 0 0 is outside [0, 1]"
    assert scene.warnings_omitted == 0

    # a scene parsed from its shipped source has the same warnings
    assert {:ok, again} = Scene.from_source(scene.source)
    assert again.warnings == scene.warnings
  end

  test "warnings past the first 100 are counted, not kept" do
    path = TestScenes.tmp_scene("many.nff", @view <> String.duplicate("s 1 1 1 0\n", 250))
    assert {:ok, scene} = Scene.load(path)
    assert length(scene.warnings) == 100
    # 250 spheres, and a scene with no objects
    assert scene.warnings_omitted == 151
  end

  test "a 60 MB single-token file gives a short error, before the token is copied" do
    path = TestScenes.tmp_scene("token.nff", String.duplicate("x", 60_000_000))
    assert {:error, %RingTracer.Error{reason: :invalid_scene, message: m}} = Scene.load(path)

    assert m ==
             "token.nff:1: a token is 60000000 bytes, more than the limit of 4096 " <>
               "(limits::MAX_TOKEN_BYTES); raise the constant in native/kernel/src/limits.rs and rebuild"
  end

  test "what cannot mean what it says is an error, not a warning" do
    path = TestScenes.tmp_scene("two.nff", @view <> "s 0 0 0 1\n" <> @view)
    assert {:error, %RingTracer.Error{reason: :invalid_scene, message: m}} = Scene.load(path)
    assert m =~ "two.nff:9: second viewpoint 'v' (the first is at line 1)"
  end
end
