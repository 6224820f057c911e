defmodule RingTracer.Cluster.Cookie do
  @moduledoc false
  # The distribution cookie, read from a file that only its owner can read.
  #
  # A cookie grants full code execution on every node that accepts it, so it
  # never goes on a command line (`/proc/PID/cmdline` is readable by every
  # local user) or in the environment: workers and renders read it from a
  # file (`--cookie-file PATH`, default `~/.erlang.cookie`) after the VM has
  # started, and set it with `Node.set_cookie/1`.
  #
  # A file that its group or others can read, write or execute is refused, with
  # the command that fixes it. `create/1` makes a new file with mode 0600 and
  # a random cookie.

  alias RingTracer.Error

  @max_bytes 4096

  @doc "The default cookie file: `~/.erlang.cookie`, the one Erlang itself uses."
  @spec default_path() :: Path.t()
  def default_path, do: Path.join(System.user_home!(), ".erlang.cookie")

  @doc """
  Reads the cookie in `path` (a regular file, mode 0600 or 0400, owned by
  this user, not empty, at most 4096 bytes).

  The file is opened once, without following a symbolic link and without
  blocking (a FIFO is refused at once), checked on that open descriptor
  and read from it, so another local user cannot swap anything in between
  the checks and the read.

      iex> dir = Path.join(System.tmp_dir!(), "rt_cookie_doc_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")
      iex> File.mkdir_p!(dir)
      iex> path = Path.join(dir, "cookie")
      iex> {:ok, ^path} = RingTracer.Cluster.Cookie.create(path)
      iex> {:ok, cookie} = RingTracer.Cluster.Cookie.read(path)
      iex> is_atom(cookie)
      true
      iex> File.chmod!(path, 0o644)
      iex> {:error, %RingTracer.Error{message: message}} = RingTracer.Cluster.Cookie.read(path)
      iex> message =~ "chmod 600"
      true
      iex> File.rm_rf!(dir) |> length()
      2
  """
  @spec read(Path.t()) :: {:ok, atom()} | {:error, Error.t()}
  def read(path) do
    with {:ok, bytes} <- read_file(path) do
      case String.trim(bytes) do
        "" ->
          {:error, Error.new(:cookie, "#{path}: the cookie file is empty")}

        cookie ->
          if String.printable?(cookie) and not String.contains?(cookie, ["\n", "\r"]),
            do: {:ok, String.to_atom(cookie)},
            else: {:error, Error.new(:cookie, "#{path}: the cookie must be one line of text")}
      end
    end
  end

  @doc """
  Creates `path` with a random 32-byte cookie and mode 0600; refuses to
  replace an existing file. Returns the path.
  """
  @spec create(Path.t()) :: {:ok, Path.t()} | {:error, Error.t()}
  def create(path) do
    cookie = 32 |> :crypto.strong_rand_bytes() |> Base.url_encode64(padding: false)
    # Made 0600 (O_EXCL, O_NOFOLLOW) in the folder opened once, filled, then
    # renamed into place in that folder with RENAME_NOREPLACE (or a hard
    # link), which refuses an existing file: never readable by others, never
    # seen partly written, never replacing anything.
    case RingTracer.Output.put(path, cookie <> "\n", 0o600, false) do
      :ok ->
        {:ok, path}

      {:error, :eexist} ->
        {:error, Error.new(:cookie, "#{path} exists already; not replacing a cookie")}

      {:error, reason} when is_atom(reason) ->
        {:error, Error.file(:cookie, path, reason)}

      {:error, message} ->
        {:error, Error.new(:cookie, "#{path}: #{message}")}
    end
  end

  defp read_file(path) do
    case RingTracer.Native.fs_read_private(Path.expand(path), @max_bytes) do
      {:ok, bytes} ->
        {:ok, bytes}

      {:error, {:enoent, _}} ->
        {:error,
         Error.new(
           :cookie,
           "#{path}: no such cookie file; create one with `ringtracer cookie #{path}` " <>
             "and copy it (mode 0600) to every node"
         )}

      {:error, {_posix, message}} ->
        {:error, Error.new(:cookie, "#{path}: the cookie file #{message}")}
    end
  end
end
