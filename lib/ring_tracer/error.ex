defmodule RingTracer.Error do
  @moduledoc """
  The error RingTracer returns in `{:error, %RingTracer.Error{}}` and raises
  from the `!` functions.

  `:reason` is a machine-readable atom, `:message` says what went wrong and,
  for scene files, where: `scene.nff:12: polygon needs at least 3 vertices`.

  | reason | when |
  |---|---|
  | `:invalid_option` | an option has the wrong type or is out of range |
  | `:file` | a file could not be read or written |
  | `:invalid_scene` | the scene failed to parse (message names file and line) |
  | `:render_failed` | the job could not complete (a crash, a failed atom) |
  | `:timeout` | the render did not finish within `:timeout` |
  | `:cancelled` | `RingTracer.cancel/1` stopped the render |
  | `:job_ended` | `RingTracer.grow/4` or `shrink/3` reached a job that is over |
  | `:not_running` | the `:ring_tracer` application is not running |
  | `:node_unavailable` | a node given in `:nodes` cannot host children (the message says why) |
  | `:build_mismatch` | another node runs another build of RingTracer (the message names both; `RingTracer.Cluster.Build`) |
  | `:cookie` | the cookie file is missing, unsafe (readable by others) or invalid |
  | `:distribution` | this node could not become distributed (name in use, epmd, TLS set-up) |
  | `:preview` | a preview could not start (port in use) or its job is not running |
  | `:farm` | a farm's head refused a request (no such job, a job that has ended) or could not start |
  | `:farm_unreachable` | a farm's head could not be reached, or did not answer in time |

  A message never holds a control character but newlines and tabs (see
  `escape/2`): a file name from an untrusted folder cannot drive the
  terminal that shows the error.
  """
  defexception [:reason, :message]

  @type t :: %__MODULE__{reason: atom(), message: String.t()}

  @doc false
  @spec new(atom(), String.t()) :: t()
  def new(reason, message) when is_atom(reason) and is_binary(message),
    do: %__MODULE__{reason: reason, message: escape(message, ["\n", "\t"])}

  @doc ~S"""
  `text` with its control characters (C0, DEL and C1), but those in `keep`,
  written as escapes the way the kernel writes them in its messages (Rust's
  `escape_debug`): `\n`, `\t`, `\r`, `\u{1b}`. Bytes that are not UTF-8
  stay as they are.

      iex> RingTracer.Error.escape("a\e[31mred\n.nff")
      "a\\u{1b}[31mred\\n.nff"
      iex> RingTracer.Error.escape("two\nlines\u0085", ["\n"])
      "two\nlines\\u{85}"
  """
  @spec escape(String.t(), [String.t()]) :: String.t()
  def escape(text, keep \\ []) when is_binary(text) do
    if String.match?(text, ~r/[\x00-\x1f\x7f]|\xc2[\x80-\x9f]/) do
      text |> String.codepoints() |> Enum.map_join(&escape_char(&1, keep))
    else
      text
    end
  end

  defp escape_char(<<c::utf8>> = char, keep) when c < 0x20 or c in 0x7F..0x9F do
    cond do
      char in keep -> char
      char == "\n" -> "\\n"
      char == "\t" -> "\\t"
      char == "\r" -> "\\r"
      true -> "\\u{" <> String.downcase(Integer.to_string(c, 16)) <> "}"
    end
  end

  defp escape_char(char, _keep), do: char

  @doc """
  A file operation on `path` that failed with `posix` (`:enoent`,
  `:eacces`, ...), as the error of reason `reason`: `"path: why"`, with
  `file_reason/2`'s words.

      iex> RingTracer.Error.file(:cookie, "/proc/version", :eacces).message
      "/proc/version: permission denied"
  """
  @spec file(atom(), Path.t(), atom()) :: t()
  def file(reason, path, posix), do: new(reason, "#{path}: #{file_reason(path, posix)}")

  @doc """
  Why a file operation on `path` failed, in words: the system's for
  `posix`, except that a missing file in a missing folder names the folder.

      iex> RingTracer.Error.file_reason("/no/such/folder/image.png", :enoent)
      "the folder /no/such/folder does not exist"
      iex> RingTracer.Error.file_reason("/tmp/no-such-file", :enoent)
      "no such file or directory"
      iex> RingTracer.Error.file_reason("/x", :enospc)
      "no space left on device"
  """
  @spec file_reason(Path.t(), atom()) :: String.t()
  def file_reason(path, :enoent) do
    dir = Path.dirname(path)
    if File.dir?(dir), do: posix_words(:enoent), else: "the folder #{dir} does not exist"
  end

  def file_reason(_path, posix), do: posix_words(posix)

  defp posix_words(posix), do: List.to_string(:file.format_error(posix))
end
