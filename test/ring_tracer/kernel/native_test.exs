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
end
