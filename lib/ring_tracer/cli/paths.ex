defmodule RingTracer.CLI.Paths do
  @moduledoc """
  Paths given on the command line, resolved against the folder the user
  called the command from: the launcher (`bin/ringtracer`) works in the
  project's folder and says in `RINGTRACER_CWD` where it was called from;
  the resident server takes it from its client (`RingTracer.CLI.Console`).
  """

  @doc "The caller's folder (see `RingTracer.CLI.Console.cwd/0`)."
  @spec cwd() :: Path.t()
  def cwd, do: RingTracer.CLI.Console.cwd()

  @doc """
  `path` made absolute against the caller's folder.

      iex> RingTracer.CLI.Paths.expand("/tmp/x.png")
      "/tmp/x.png"
  """
  @spec expand(Path.t()) :: Path.t()
  def expand(path) when is_binary(path), do: Path.expand(path, cwd())

  @doc "The values of `keys` in `opts` made absolute (each may be repeated)."
  @spec expand(keyword(), [atom()]) :: keyword()
  def expand(opts, keys) when is_list(opts) do
    Enum.map(opts, fn {k, v} -> if k in keys, do: {k, expand(v)}, else: {k, v} end)
  end
end
