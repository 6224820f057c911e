defmodule Mix.Tasks.RingTracer.Farm do
  @shortdoc "Starts a farm's head: a queue of jobs that workers join"
  @moduledoc """
  Starts a farm's head (`RingTracer.Farm.start_head/1`) on a distributed
  node and keeps it up until it is stopped (Ctrl-C twice, or SIGTERM).

      mix ring_tracer.farm [--sname NAME] [--dir DIR] [--cookie-file PATH]
        [--listen ADDR] [--ports MIN-MAX] [--tls DIR]

  The options are `RingTracer.CLI.Farm.Head`'s (docs/farm.md); workers join
  with `bin/ringtracer worker --join farm@localhost` (or `mix
  ring_tracer.worker --join farm@localhost`).
  """
  use Mix.Task

  @impl Mix.Task
  def run(argv) do
    case RingTracer.CLI.Farm.Head.start(argv) do
      :help ->
        Mix.shell().info(RingTracer.CLI.Farm.Head.help())

      {:ok, _node, text} ->
        Mix.shell().info(String.trim_trailing(text))
        Process.sleep(:infinity)

      {:error, _status, message} ->
        Mix.raise(message)
    end
  end
end
