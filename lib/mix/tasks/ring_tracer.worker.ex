defmodule Mix.Tasks.RingTracer.Worker do
  @shortdoc "Starts a node that hosts children for renders on other nodes"
  @moduledoc """
  Starts a distributed node running `:ring_tracer`, ready to host children
  of renders started on other nodes, and keeps it up until it is stopped
  (Ctrl-C twice, or SIGTERM).

      mix ring_tracer.worker --sname NAME [--cookie-file PATH] [--listen ADDR]
        [--ports MIN-MAX] [--tls DIR]
      mix ring_tracer.worker --join HEAD [--tags a,b] [--slots N] [--speed F] ...

  The options are `RingTracer.CLI.Worker`'s. Start workers on loopback and
  render with children on them:

      bin/ringtracer worker --sname w1 &
      bin/ringtracer render priv/scenes/balls_s2.nff --out balls.png --nodes w1@localhost
  """
  use Mix.Task

  @impl Mix.Task
  def run(argv) do
    case RingTracer.CLI.Worker.start(argv) do
      {:ok, _node, line} ->
        Mix.shell().info(line)
        Process.sleep(:infinity)

      {:error, message} ->
        Mix.raise(message)
    end
  end
end
