defmodule RingTracer.CLI do
  @moduledoc """
  The command line, booted straight from `erl` (no Mix):

      erl -noshell -pa ... -s Elixir.RingTracer.CLI main -extra worker --sname w1

  Commands: `worker` (`RingTracer.CLI.Worker`). Exit status: 0 ok, 1 a
  failure, 2 a usage error.
  """

  @doc "Runs the command in the VM's plain arguments (those after `-extra`)."
  @spec main() :: no_return()
  def main, do: main(Enum.map(:init.get_plain_arguments(), &List.to_string/1))

  @doc "Runs a command."
  @spec main([String.t()]) :: no_return()
  def main(args) do
    case args do
      ["worker" | argv] ->
        case RingTracer.CLI.Worker.start(argv) do
          {:ok, _node, line} ->
            IO.puts(line)
            Process.sleep(:infinity)

          {:error, message} ->
            halt(message, 1)
        end

      other ->
        halt("unknown command: #{Enum.join(other, " ")}; known: worker", 2)
    end
  end

  @spec halt(String.t(), non_neg_integer()) :: no_return()
  defp halt(message, status) do
    IO.puts(:stderr, "ringtracer: #{message}")
    System.halt(status)
  end
end
