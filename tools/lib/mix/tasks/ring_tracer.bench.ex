defmodule Mix.Tasks.RingTracer.Bench do
  @shortdoc "Benchmarks: the kernel against POV-Ray, and the ring against the kernel"

  # A benchmark is a module implementing `RingTracer.Bench`, and its line here.
  @benchmarks [
    {"kernel", RingTracer.Bench.Kernel},
    {"balance", RingTracer.Bench.Balance},
    {"nodes", RingTracer.Bench.Nodes},
    {"startup", RingTracer.Bench.Startup},
    {"limits", RingTracer.Bench.Limits},
    {"rays", RingTracer.Bench.Rays},
    {"network", RingTracer.Bench.Network},
    {"preview", RingTracer.Bench.Preview},
    {"sequence", RingTracer.Bench.Sequence},
    {"farm", RingTracer.Bench.Farm}
  ]

  @moduledoc """
  Benchmarks that print figures side by side from one run:

  #{Enum.map_join(@benchmarks, "\n", fn {name, module} -> "    mix ring_tracer.bench #{name}  (`#{inspect(module)}`)" end)}

  Each is a module implementing `RingTracer.Bench`; a new one is a module
  and one line in this task's table.

  #{Enum.map_join(@benchmarks, "\n", fn {name, module} -> "## #{name}\n\n" <> module.help() end)}
  """
  use Mix.Task

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
