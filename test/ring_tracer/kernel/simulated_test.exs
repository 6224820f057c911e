defmodule RingTracer.Kernel.SimulatedTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Kernel.Simulated

  alias RingTracer.Kernel.Simulated

  test "an atom's work units are its cost in the model, whatever its measured time" do
    costs = Simulated.pack([1_000, 3_000])
    {:ok, pixels, rays, us} = Simulated.trace(costs, 0, 4, 1)
    assert byte_size(pixels) == 4 * 12
    assert rays.work == 3_000
    assert rays.eye == 0
    assert us >= 3_000
  end

  defp spec(layout) do
    %RingTracer.Job.Spec{
      id: make_ref(),
      source: nil,
      settings: nil,
      layout: layout,
      caller: self()
    }
  end

  test "in a job of several frames every frame costs alike: atoms cost by their place in the frame" do
    layout = RingTracer.Layout.new(8, 1, 2, 2) |> RingTracer.Layout.with_frames(3)
    opts = [costs: fn a -> (a + 1) * 100 end]
    {:ok, context} = Simulated.prepare(spec(layout), opts)

    for a <- RingTracer.Layout.atoms(layout) do
      {first, count} = RingTracer.Layout.span(layout, a)
      {:ok, pixels, rays, _us} = Simulated.trace(context, first, count, a)
      assert byte_size(pixels) == count * 12
      assert rays.work == (rem(a, 4) + 1) * 100, "atom #{a}"
    end

    # a piece of atom 1 of frame 1 costs its share of that atom
    {:ok, _, rays, _} = Simulated.trace(context, 2, 1, {5, 1, 2, 2})
    assert rays.work == 100

    # the preview is of one frame's atoms
    assert Simulated.atom_work(spec(layout), opts) == {:ok, {100, 200, 300, 400}}
  end

  test "a job of one frame traces with the costs themselves" do
    layout = RingTracer.Layout.new(8, 1, 2, 2)
    costs = Simulated.pack([1, 2, 3, 4])
    assert Simulated.prepare(spec(layout), costs: costs) == {:ok, costs}
    assert Simulated.atom_work(spec(layout), costs: costs) == {:ok, {1, 2, 3, 4}}
  end
end
