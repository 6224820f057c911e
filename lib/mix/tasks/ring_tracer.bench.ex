defmodule Mix.Tasks.RingTracer.Bench do
  @shortdoc "Benchmarks: the kernel against POV-Ray, and the ring against the kernel"
  @moduledoc """
  Benchmarks that print figures side by side from one run.

      mix ring_tracer.bench kernel [--scenes a,b] [--dir DIR] [--pov-dir DIR] [--runs R]
                                   [--size 512] [--threads 2] [--children 8] [--atoms 16]
      mix ring_tracer.bench balance [--size 1024] [--atoms 16] [--runs 3] [--quick]
      mix ring_tracer.bench nodes [--scene FILE] [--children 6] [--runs 3]
      mix ring_tracer.bench startup [--scenes a,b] [--runs 5] [--size 512]
      mix ring_tracer.bench limits [--quick]
      mix ring_tracer.bench rays MESH.obj [MORE.obj ...]

  Each benchmark is a module, documented there:

    * `kernel` — `RingTracer.Bench.Kernel`: our set-up and trace times
      against POV-Ray's on the SPD scenes, and the ring against the kernel;
    * `balance` — `RingTracer.Bench.Balance`: every strategy on real and
      simulated scenarios, makespan / ideal and messages per atom, with the
      targets of `RingTracer.Bench.Targets` checked under the table;
    * `nodes` — `RingTracer.Bench.Nodes`: one node against three;
    * `startup` — `RingTracer.Bench.Startup`: the whole command against
      POV-Ray's whole process, and the time to the first atom;
    * `limits` — `RingTracer.Bench.Limits`: every documented maximum at
      full size;
    * `rays` — `RingTracer.Bench.Rays`: closest-hit rays per second in the
      kernel alone.

  A new benchmark is a module implementing `RingTracer.Bench` and one line
  in this task's table.
  """
  use Mix.Task

  @benchmarks [
    {"kernel", RingTracer.Bench.Kernel},
    {"balance", RingTracer.Bench.Balance},
    {"nodes", RingTracer.Bench.Nodes},
    {"startup", RingTracer.Bench.Startup},
    {"limits", RingTracer.Bench.Limits},
    {"rays", RingTracer.Bench.Rays}
  ]

  @impl Mix.Task
  def run([name | argv]) do
    case List.keyfind(@benchmarks, name, 0) do
      {_, benchmark} -> benchmark.run(argv)
      nil -> usage()
    end
  end

  def run([]), do: usage()

  @spec usage() :: no_return()
  defp usage do
    Mix.raise(
      "usage: mix ring_tracer.bench #{Enum.map_join(@benchmarks, "|", &elem(&1, 0))} [options]" <>
        "  (see mix help ring_tracer.bench)"
    )
  end
end
