defmodule RingTracer.Job.SpecTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Spec
end
