defmodule Mix.Tasks.RingTracer.Cookie do
  @shortdoc "Creates a cookie file (mode 0600) for a cluster"
  @moduledoc """
  Creates a cookie file with a random cookie, readable by its owner only,
  and refuses to replace one that exists.

      mix ring_tracer.cookie [PATH]

  `PATH` defaults to `~/.erlang.cookie`, which every node reads unless
  given `--cookie-file`. Copy the file (keeping its mode) to every machine
  of the cluster: anyone who has it can run any code on every node.
  """
  use Mix.Task

  @impl Mix.Task
  def run(argv) do
    path =
      case argv do
        [] -> RingTracer.Cluster.Cookie.default_path()
        [path] -> RingTracer.CLI.Paths.expand(path)
        _ -> Mix.raise("usage: mix ring_tracer.cookie [PATH]")
      end

    case RingTracer.Cluster.Cookie.create(path) do
      {:ok, path} -> Mix.shell().info("wrote a new cookie to #{path} (mode 0600)")
      {:error, error} -> Mix.raise(error.message)
    end
  end
end
