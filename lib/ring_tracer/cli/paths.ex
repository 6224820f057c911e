defmodule RingTracer.CLI.Paths do
  @moduledoc false
  # Paths given on the command line, resolved against the folder the user
  # called the command from: the launcher (`bin/ringtracer`) works in the
  # project's folder and says in `RINGTRACER_CWD` where it was called from;
  # the resident server takes it from its client (`RingTracer.CLI.Console`).

  @doc "The caller's folder (see `RingTracer.CLI.Console.cwd/0`)."
  @spec cwd() :: Path.t()
  def cwd, do: RingTracer.CLI.Console.cwd()

  @doc """
  `path` made absolute against the caller's folder; a leading `~` is the
  caller's home (`RingTracer.CLI.Console.home/0`: also through the server,
  whose own home may differ).

      iex> RingTracer.CLI.Paths.expand("/tmp/x.png")
      "/tmp/x.png"
      iex> RingTracer.CLI.Paths.expand("~/x.png") == Path.join(System.user_home!(), "x.png")
      true
  """
  @spec expand(Path.t()) :: Path.t()
  def expand("~"), do: Path.expand(RingTracer.CLI.Console.home())
  def expand("~/" <> rest), do: Path.expand(rest, RingTracer.CLI.Console.home())
  def expand(path) when is_binary(path), do: Path.expand(path, cwd())

  @doc "The values of `keys` in `opts` made absolute (each may be repeated)."
  @spec expand(keyword(), [atom()]) :: keyword()
  def expand(opts, keys) when is_list(opts) do
    Enum.map(opts, fn {k, v} -> if k in keys, do: {k, expand(v)}, else: {k, v} end)
  end
end
