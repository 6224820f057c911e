defmodule RingTracer.Job.ChildTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Child
end
