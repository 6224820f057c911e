defmodule RingTracer.Kernel.NativeTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Kernel.Native

  alias RingTracer.{Layout, Scene, Settings}
  alias RingTracer.Job.Spec
  alias RingTracer.Kernel.Native
  alias RingTracer.Scene.Source
  alias RingTracer.TestScenes

  defp spec(name, width, height, children, atoms) do
    scene = Scene.load!(TestScenes.path(name))

    %Spec{
      id: make_ref(),
      source: scene.source,
      settings: %Settings{width: width, height: height},
      layout: Layout.new(width, height, children, atoms),
      caller: self()
    }
  end

  test "atom_work previews each atom's work: close to what tracing it costs, busy rows dearer" do
    spec = spec("balls_s2.nff", 256, 256, 4, 4)
    {:ok, work} = Native.atom_work(spec, [])
    assert tuple_size(work) == 16

    {:ok, context} = Native.prepare(spec, [])

    traced =
      for a <- Layout.atoms(spec.layout) do
        {first, count} = Layout.span(spec.layout, a)
        {:ok, _pixels, rays, _us} = Native.trace(context, first, count, a)
        rays.work
      end

    # the whole image's work, previewed from about 1,024 pixels of 65,536
    total = Enum.sum(traced)
    assert_in_delta Enum.sum(Tuple.to_list(work)) / total, 1.0, 0.15

    # the preview ranks the atoms as tracing them does: the dearest quarter
    # by preview is dearer than the cheapest quarter by trace
    by_preview = Enum.sort_by(0..15, &elem(work, &1))
    cheap = Enum.take(by_preview, 4) |> Enum.map(&Enum.at(traced, &1)) |> Enum.sum()
    dear = Enum.take(by_preview, -4) |> Enum.map(&Enum.at(traced, &1)) |> Enum.sum()
    assert dear > 1.5 * cheap
  end

  test "atom_work of a scene that no longer parses is an error, not a crash" do
    spec = spec("balls_s1.nff", 16, 16, 2, 2)
    bad = %{spec | source: Source.new("bad.nff", spec.source.format, "s 0 0 oops\n", %{})}
    assert {:error, message} = Native.atom_work(bad, [])
    assert is_binary(message)
  end

  # `work` is what the tracing cost, and coherent rays traced as packets
  # cost less: it depends on how pixels are grouped, the rays do not.
  defp rays_only(rays), do: Map.delete(rays, :work)

  test "a short atom gives the same pixels and rays on its own scheduler as on a dirty one" do
    spec = spec("balls_s2.nff", 64, 64, 1, 64)
    {:ok, {scene, native} = context} = Native.prepare(spec, [])

    for {first, count} <- [{0, 1}, {100, 7}, {640, 64}, {1000, 256}, {2000, 257}] do
      {:ok, {dirty, dirty_rays, _}} =
        RingTracer.Native.trace_atom(scene.ref, native, first, count)

      assert {:ok, pixels, rays, _us} = Native.trace(context, first, count, 0)

      assert {pixels, rays_only(rays)} == {dirty, rays_only(dirty_rays)},
             "#{count} pixels from #{first}"
    end
  end

  test "the normal-scheduler call stops at its budget, on a chunk boundary, and the rest is traced dirty" do
    spec = spec("balls_s2.nff", 64, 64, 1, 64)
    {:ok, {scene, native}} = Native.prepare(spec, [])
    {:ok, {whole, whole_rays, _}} = RingTracer.Native.trace_atom(scene.ref, native, 0, 256)

    # no budget: one chunk of eight pixels, then it stops
    assert {:ok, {head, head_rays, _us, 8}} =
             RingTracer.Native.trace_atom_short(scene.ref, native, 0, 256, 0)

    assert byte_size(head) == 8 * 12
    {:ok, {rest, rest_rays, _}} = RingTracer.Native.trace_atom(scene.ref, native, 8, 248)
    assert head <> rest == whole
    assert rays_only(RingTracer.Rays.add(head_rays, rest_rays)) == rays_only(whole_rays)

    # a span past the image is refused before anything is traced
    assert {:error, _} = RingTracer.Native.trace_atom_short(scene.ref, native, 4090, 16, 200)
  end

  # A job of `frames` (scene frames, from 0), one layout frame each.
  defp frames_spec(name, width, height, children, atoms, frames) do
    spec = spec(name, width, height, children, atoms)
    %{spec | layout: Layout.with_frames(spec.layout, length(frames)), frames: frames}
  end

  defp trace_all(spec, context, atoms) do
    for a <- atoms, into: %{} do
      {first, count} = Layout.span(spec.layout, a)
      assert {:ok, pixels, _rays, _us} = Native.trace(context, first, count, a)
      assert byte_size(pixels) == count * 12
      {a, pixels}
    end
  end

  # Every atom of every frame, frame after frame in turn (a grandchild of a
  # job with several frames in flight moves between them), some in pieces.
  defp round_robin(layout) do
    0..(layout.frames - 1)
    |> Enum.map(&Enum.to_list(Layout.frame_atoms(layout, &1)))
    |> Enum.zip()
    |> Enum.flat_map(&Tuple.to_list/1)
    |> Enum.flat_map(fn a ->
      if rem(a, 2) == 1, do: Tuple.to_list(Layout.split(a, 1, 3)), else: [a]
    end)
  end

  for name <- ["whitted_orbit.toml", "balls_flythrough.toml"] do
    test "a job of several frames of #{name} traces each atom in its frame's scene, byte for byte" do
      frames = [0, 5, 11]

      # atoms of 128 pixels (traced first on the grandchild's scheduler) and of 384 (dirty)
      for {children, atoms} <- [{2, 3}, {2, 1}] do
        spec = frames_spec(unquote(name), 32, 24, children, atoms, frames)
        assert {:ok, context} = Native.prepare(spec, [])
        traced = trace_all(spec, context, round_robin(spec.layout))

        for {frame, i} <- Enum.with_index(frames) do
          image =
            traced
            |> Enum.filter(fn {a, _} -> Layout.frame(spec.layout, a) == i end)
            |> Enum.sort_by(fn {a, _} -> Layout.span(spec.layout, a) end)
            |> Enum.map_join(&elem(&1, 1))

          # the kernel's own render of that frame, and a job of that frame alone
          assert image == TestScenes.reference(unquote(name), 32, 24, frame: frame + 1),
                 "frame #{frame}, #{children}x#{atoms} atoms"

          single = %{spec(unquote(name), 32, 24, children, atoms) | frames: [frame]}
          {:ok, single_context} = Native.prepare(single, [])
          alone = trace_all(single, single_context, Layout.atoms(single.layout))
          assert image == Enum.map_join(Layout.atoms(single.layout), &alone[&1])
        end
      end
    end
  end

  test "frames differ: the frames of a job are not all traced in one scene" do
    spec = frames_spec("whitted_orbit.toml", 16, 12, 1, 1, [0, 5])
    {:ok, context} = Native.prepare(spec, [])
    {:ok, frame0, _, _} = Native.trace(context, 0, 192, 0)
    {:ok, frame5, _, _} = Native.trace(context, 0, 192, 1)
    assert frame0 != frame5
  end

  test "atom_work of a job of several frames is that of its first frame's atoms" do
    spec = frames_spec("whitted_orbit.toml", 64, 48, 2, 4, [11, 0, 5])
    single = %{spec("whitted_orbit.toml", 64, 48, 2, 4) | frames: [11]}
    assert {:ok, work} = Native.atom_work(spec, [])
    assert tuple_size(work) == 8
    assert {:ok, work} == Native.atom_work(single, [])
    assert {:ok, work} != Native.atom_work(%{single | frames: [0]}, [])
  end

  test "frames past the scene's last, or not one per layout frame, are errors, not crashes" do
    spec = frames_spec("whitted_orbit.toml", 16, 12, 2, 2, [0, 5, 48])
    assert {:error, message} = Native.prepare(spec, [])
    assert message =~ "no frame 48"
    assert {:error, ^message} = Native.atom_work(spec, [])

    assert {:error, message} = Native.prepare(%{spec | frames: [0, 5]}, [])
    assert message =~ "2 scene frame(s) for a layout of 3"

    assert {:error, message} = Native.prepare(%{spec | frames: [0, -1, 2]}, [])
    assert message =~ "no frame -1"

    single = %{spec("whitted_orbit.toml", 16, 12, 2, 2) | frames: [48]}
    assert {:error, message} = Native.prepare(single, [])
    assert message =~ "no frame 48"

    # an atom past the job's frames
    {:ok, context} = Native.prepare(%{spec | frames: [0, 5, 11]}, [])
    assert {:error, message} = Native.trace(context, 0, 4, 12)
    assert message =~ "past the job's 3 frames"
  end
end
