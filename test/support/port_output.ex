defmodule RingTracer.Test.PortOutput do
  @moduledoc """
  The output of an OS command run through a port (`:binary`, `:exit_status`,
  `:stderr_to_stdout`), for tests of the launcher as users run it.
  """
  import ExUnit.Assertions, only: [flunk: 1]

  @wait_ms 120_000

  @doc "Everything `port` writes until its command exits: `{status, output}`."
  @spec collect(port(), binary()) :: {non_neg_integer(), binary()}
  def collect(port, out \\ "") do
    receive do
      {^port, {:data, data}} -> collect(port, out <> data)
      {^port, {:exit_status, status}} -> {status, out}
    after
      @wait_ms -> flunk("the command did not end; output: #{out}")
    end
  end

  @doc "What `port` writes until `text` appears in it (the command goes on)."
  @spec until(port(), String.t(), binary()) :: binary()
  def until(port, text, out \\ "") do
    if String.contains?(out, text) do
      out
    else
      receive do
        {^port, {:data, data}} ->
          until(port, text, out <> data)

        {^port, {:exit_status, status}} ->
          flunk("exited #{status} before #{inspect(text)}: #{out}")
      after
        @wait_ms -> flunk("no #{inspect(text)}; output: #{out}")
      end
    end
  end
end
