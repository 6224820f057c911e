defmodule RingTracer.Test.SecondUser do
  @moduledoc """
  A second local user for tests that play an attacker: made with `useradd`
  (no home, no shell) when it does not exist yet, which needs root.
  """

  @doc "Makes the user `name` unless it exists: `:ok`, or `:error` when it cannot."
  @spec ensure(String.t()) :: :ok | :error
  def ensure(name) do
    case System.cmd("id", [name], stderr_to_stdout: true) do
      {_, 0} ->
        :ok

      _ ->
        {_, status} =
          System.cmd("useradd", ["--no-create-home", "--shell", "/usr/sbin/nologin", name],
            stderr_to_stdout: true
          )

        if status == 0, do: :ok, else: :error
    end
  end
end
