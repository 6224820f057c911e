defmodule RingTracer.RaysTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Rays

  alias RingTracer.{Layout, Rays, Scene, SceneCache, Settings}
  alias RingTracer.Job.Spec
  alias RingTracer.TestScenes

  test "a traced atom's counters have the kernel's names, and every kernel's zero is the same" do
    scene = Scene.load!(TestScenes.path("balls_s1.nff"))
    :ok = SceneCache.put(scene)

    spec = %Spec{
      id: make_ref(),
      source: scene.source,
      settings: %Settings{width: 16, height: 16},
      layout: Layout.new(16, 16, 1, 1),
      caller: self()
    }

    {:ok, context} = RingTracer.Kernel.Native.prepare(spec, [])
    {:ok, _pixels, rays, _us} = RingTracer.Kernel.Native.trace(context, 0, 256, 0)
    assert Map.keys(rays) == Map.keys(Rays.zero())
    assert rays.eye == 256
    assert Rays.total(rays) == rays.eye + rays.reflected + rays.refracted + rays.shadow
    assert RingTracer.Kernel.no_rays() == Rays.zero()
  end
end
