defmodule RingTracer.NativeTest do
  # The NIF calls of RingTracer.Native that the modules above it do not wrap (yet): the
  # animation of a parsed scene, the scene resource of one of its frames and its camera.
  use ExUnit.Case, async: true

  alias RingTracer.{Native, Scene, Settings, TestScenes}

  defp parse(name) do
    path = TestScenes.path(name)
    format = String.trim_leading(Path.extname(path), ".")
    {:ok, {bytes, _real, dir}} = Native.read_scene_file(path)

    {:ok, {ref, _info, _files, _paths}} =
      Native.scene_parse(bytes, format, Path.basename(path), dir, [], %{})

    ref
  end

  defp pixels(ref) do
    settings = Settings.to_native(%Settings{width: 24, height: 18})
    {:ok, {pixels, _rays, _us}} = Native.trace_atom(ref, settings, 0, 24 * 18)
    pixels
  end

  test "a still is one frame at clock 0, and its frame 0 is the scene" do
    ref = parse("whitted.toml")

    assert Native.scene_animation(ref) == %{
             frames: 1,
             clock_start: 0.0,
             clock_end: 0.0,
             cyclic: false,
             moves_objects: false,
             rebuilds_primitives: false
           }

    assert {:ok, frame} = Native.scene_frame(ref, 0)
    assert pixels(frame) == pixels(ref)
    assert {:error, message} = Native.scene_frame(ref, 1)
    assert message =~ "frame 1 of an animation of 1 frames"
  end

  test "an animated scene gives its frame count, clock range and each frame to trace" do
    ref = parse("whitted_orbit.toml")

    assert %{
             frames: 48,
             clock_start: +0.0,
             clock_end: 1.0,
             cyclic: true,
             moves_objects: true,
             rebuilds_primitives: true
           } = Native.scene_animation(ref)

    # the scene as parsed is frame 0
    {:ok, f0} = Native.scene_frame(ref, 0)
    {:ok, f12} = Native.scene_frame(ref, 12)
    assert pixels(f0) == pixels(ref)
    assert pixels(f12) != pixels(f0)

    # a frame is the same whichever frame's resource it is made from
    {:ok, f12_again} = Native.scene_frame(f0, 12)
    {:ok, f11} = Native.scene_frame(f12, 11)
    {:ok, f12_from_11} = Native.scene_frame(f11, 12)
    assert pixels(f12_again) == pixels(f12)
    assert pixels(f12_from_11) == pixels(f12)
    assert Native.scene_animation(f12) == Native.scene_animation(ref)

    assert {:error, message} = Native.scene_frame(ref, 48)
    assert message =~ "frame 48 of an animation of 48 frames (they count from 0)"
  end

  test "a camera flight through an included SPD scene" do
    ref = parse("balls_flythrough.toml")

    assert %{frames: 24, cyclic: false, moves_objects: false, rebuilds_primitives: false} =
             Native.scene_animation(ref)

    # the included file counts: 820 spheres and the floor
    assert Scene.load!(TestScenes.path("balls_flythrough.toml")).primitives == 821
    {:ok, last} = Native.scene_frame(ref, 23)
    assert pixels(last) != pixels(ref)
  end

  test "a scene's camera and each frame's, as the kernel keeps them" do
    ref = parse("balls_flythrough.toml")
    close = fn {a, b, c}, {x, y, z} -> abs(a - x) + abs(b - y) + abs(c - z) < 1.0e-5 end

    # the first frame's view is the NFF's: from (2.1, 1.3, 1.7) at the origin, up z, fov 45
    cam = Native.scene_camera(ref)
    assert close.(cam.from, {2.1, 1.3, 1.7})
    n = :math.sqrt(2.1 * 2.1 + 1.3 * 1.3 + 1.7 * 1.7)
    assert close.(cam.forward, {-2.1 / n, -1.3 / n, -1.7 / n})
    # right = forward x up, normalised (here horizontal); up = right x forward
    h = :math.sqrt(2.1 * 2.1 + 1.3 * 1.3)
    assert close.(cam.right, {-1.3 / h, 2.1 / h, 0.0})
    {rx, ry, rz} = cam.right
    {fx, fy, fz} = cam.forward
    assert close.(cam.up, {ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx})
    assert abs(cam.fov - 45.0) < 1.0e-4

    # the last frame's, at the path's last key
    {:ok, last} = Native.scene_frame(ref, 23)
    assert close.(Native.scene_camera(last).from, {-0.9, -0.6, 1.6})
  end

  test "the sequence benchmark's flight round tetra_s6 starts at the NFF's own view" do
    ref = parse("tetra_flythrough.toml")

    assert %{frames: 48, moves_objects: false, rebuilds_primitives: false} =
             Native.scene_animation(ref)

    assert Scene.load!(TestScenes.path("tetra_flythrough.toml")).primitives ==
             Scene.load!(TestScenes.path("spd/tetra_s6.nff")).primitives

    assert Native.scene_camera(ref) == Native.scene_camera(parse("spd/tetra_s6.nff"))
    {:ok, last} = Native.scene_frame(ref, 47)
    assert Native.scene_camera(last).from != Native.scene_camera(ref).from
  end

  test "bad animation input is an error naming file and line, not a crash" do
    bad = """
    [animation]
    frames = 4
    [camera]
    from = [0, 0, 5]
    at = [0, 0, 0]
    [camera.animate.fov]
    keys = [{ clock = 0.5, value = 30 },
            { clock = 0.25, value = 40 }]
    """

    assert {:error, message} = Native.scene_parse(bad, "toml", "bad.toml", nil, [], %{})
    assert message =~ "bad.toml:8: the camera 'fov': keys out of order"
  end
end
