defmodule RingTracer.Distribution do
  @moduledoc """
  Makes the current node distributed for the mix tasks: `--sname NAME` or
  `--name NAME@HOST`, and `--cookie C`. epmd is started if it is not
  running. A node that is already distributed (started with
  `elixir --sname X --cookie C -S mix ...`) is left as it is, apart from the
  cookie when one is given.
  """

  @doc """
  Starts distribution from parsed options (`:sname`, `:name`, `:cookie`);
  `generate: true` makes up a short name when none is given. Raises
  `Mix.Error` with the reason when the node cannot start.
  """
  @spec start!(keyword(), keyword()) :: :ok
  def start!(opts, flags \\ []) do
    unless Node.alive?() do
      {name, type} =
        cond do
          opts[:name] -> {opts[:name], :longnames}
          opts[:sname] -> {opts[:sname], :shortnames}
          flags[:generate] -> {"ring_tracer_#{System.unique_integer([:positive])}", :shortnames}
          true -> Mix.raise("give the node a name: --sname NAME (or --name NAME@HOST)")
        end

      System.cmd("epmd", ["-daemon"], stderr_to_stdout: true)

      case Node.start(String.to_atom(name), type) do
        {:ok, _} -> :ok
        {:error, reason} -> Mix.raise("could not start node #{name}: #{inspect(reason)}")
      end
    end

    if cookie = opts[:cookie], do: Node.set_cookie(String.to_atom(cookie))
    :ok
  end
end
