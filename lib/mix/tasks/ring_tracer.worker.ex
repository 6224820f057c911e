defmodule Mix.Tasks.RingTracer.Worker do
  @shortdoc "Starts a node that hosts children for renders on other nodes"
  @moduledoc """
  Starts a distributed node running `:ring_tracer`, ready to host children
  of renders started on other nodes, and keeps it up until it is stopped
  (Ctrl-C twice, or SIGTERM).

      mix ring_tracer.worker --sname NAME [--cookie COOKIE]
      mix ring_tracer.worker --name NAME@HOST [--cookie COOKIE]

  `--sname` uses short host names (nodes on one machine or one domain),
  `--name` long ones. The cookie must be the same on every node of a render;
  without `--cookie` the node uses `~/.erlang.cookie`.
  """
  use Mix.Task

  @impl Mix.Task
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv, strict: [sname: :string, name: :string, cookie: :string])

    RingTracer.Distribution.start!(opts)
    Mix.Task.run("app.start")

    Mix.shell().info(
      "RingTracer worker #{node()} ready (cookie from #{if opts[:cookie], do: "--cookie", else: "~/.erlang.cookie"})"
    )

    Process.sleep(:infinity)
  end
end
