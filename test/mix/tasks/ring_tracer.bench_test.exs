defmodule Mix.Tasks.RingTracer.BenchTest do
  use ExUnit.Case, async: true

  alias Mix.Tasks.RingTracer.Bench, as: Task

  test "an unknown benchmark names every benchmark the task knows" do
    error = assert_raise Mix.Error, fn -> Task.run(["nope"]) end
    assert error.message =~ "kernel|balance|nodes|startup|limits|rays"
    assert_raise Mix.Error, ~r/usage/, fn -> Task.run([]) end
  end

  test "rays needs meshes" do
    assert_raise Mix.Error, ~r/usage: mix ring_tracer.bench rays MESH.obj/, fn ->
      Task.run(["rays"])
    end
  end
end
