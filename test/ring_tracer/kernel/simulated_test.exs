defmodule RingTracer.Kernel.SimulatedTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Kernel.Simulated
end
