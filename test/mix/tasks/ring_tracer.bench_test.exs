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

  test "mix help shows every benchmark's own documentation" do
    {:docs_v1, _, _, _, %{"en" => doc}, _, _} = Code.fetch_docs(Task)

    for module <- [RingTracer.Bench.Kernel, RingTracer.Bench.Balance, RingTracer.Bench.Rays] do
      assert doc =~ module.help()
    end
  end
end
