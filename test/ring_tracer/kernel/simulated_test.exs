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
end
