defmodule RingTracer.CLI.Server do
  @moduledoc false
  # A resident render node for the command line (`ringtracer serve`).
  #
  # A command booted in a VM of its own pays for the boot: the emulator, then
  # loading Elixir and the application, a few tenths of a second before the
  # first atom. A running server has all of that done: `bin/ringtracer render`
  # finds its socket, and a small client (`native/client`, no BEAM) hands it
  # the arguments, the caller's folder and whether stderr is a terminal, then
  # relays what the command writes and its exit status. Interrupts go the
  # same way (the client's first Ctrl-C or SIGTERM cancels the job); a client
  # that goes away cancels its job too.
  #
  # The socket is a Unix socket in a folder only its owner can enter (mode
  # 0700, checked at start), so only that user (and root) can reach it; the
  # commands run with the server's rights, which are the same user's.
  # Renders on other nodes (`--nodes`, `--tls`, ...) start distribution,
  # which a command's own VM does: the server tells the client to boot one
  # (`RingTracer.CLI.Server.Session`).

  use GenServer
  require Logger

  alias RingTracer.CLI.Server.Session

  @typedoc """
  The listening socket and where it is: `path` as users name it, `local`
  the same through the folder `dir` held open.
  """
  @type t :: %__MODULE__{
          socket: :gen_tcp.socket(),
          path: Path.t(),
          acceptor: pid(),
          dir: reference(),
          local: Path.t()
        }
  defstruct [:socket, :path, :acceptor, :dir, :local]

  @typedoc "What runs a command: its arguments, whether signals reach it; its exit status."
  @type runner :: ([String.t()] -> non_neg_integer())

  @doc """
  Listens on the Unix socket `path` (its folder is made, mode 0700, if
  missing) and runs each client's command with `runner`
  (`&RingTracer.CLI.run/2`).
  """
  @spec start_link(Path.t(), runner()) :: GenServer.on_start()
  def start_link(path, runner), do: GenServer.start_link(__MODULE__, {path, runner})

  @doc "Stops the server and removes its socket."
  @spec stop(pid()) :: :ok
  def stop(pid), do: GenServer.stop(pid)

  @doc """
  Checks that `dir` can hold the socket: made if missing (mode 0700 in the
  one `mkdir`), then opened without following a symbolic link and checked on
  that descriptor: a folder owned by this user that nobody else can enter.
  """
  @spec check_dir(Path.t()) :: :ok | {:error, String.t()}
  def check_dir(dir) do
    with {:ok, _held} <- open_dir(dir), do: :ok
  end

  # The socket's folder, made and checked as check_dir/1 says, held open: a
  # path through the descriptor (/proc/self/fd/N) names that very folder in
  # this OS process for as long as the handle lives, whatever is done to its
  # name meanwhile.
  defp open_dir(dir) do
    full = Path.expand(dir)

    with :ok <- make_parent(full),
         {:ok, held} <- RingTracer.Native.fs_private_dir(full, true) do
      {:ok, held}
    else
      {:error, {nil, message}} -> {:error, "#{dir} #{message}"}
      {:error, {posix, _message}} -> {:error, "#{dir}: #{:file.format_error(posix)}"}
      {:error, reason} -> {:error, "#{Path.dirname(dir)}: #{:file.format_error(reason)}"}
    end
  end

  # The folders above the socket's are the user's own business (~/.cache,
  # $XDG_RUNTIME_DIR): made if missing, as mkdir -p would.
  defp make_parent(dir), do: File.mkdir_p(Path.dirname(dir))

  @impl GenServer
  def init({path, runner}) do
    Process.flag(:trap_exit, true)

    # the socket is made, checked and removed through the folder held open
    with {:ok, held} <- open_dir(Path.dirname(path)),
         local = Path.join(RingTracer.Native.fs_dir_path(held), Path.basename(path)),
         :ok <- clear_stale(local, path),
         {:ok, socket} <- listen(local),
         :ok <- File.chmod(local, 0o600) do
      server = self()
      acceptor = spawn_link(fn -> accept(socket, server, runner) end)
      {:ok, %__MODULE__{socket: socket, path: path, acceptor: acceptor, dir: held, local: local}}
    else
      {:error, message} when is_binary(message) -> {:stop, message}
      {:error, reason} -> {:stop, "cannot listen on #{path}: #{inspect(reason)}"}
    end
  end

  # A socket file left by a server that died: nobody answers on it. `local`
  # names it through the folder held open; `path` is the name users know.
  defp clear_stale(local, path) do
    case File.lstat(local) do
      {:error, :enoent} ->
        :ok

      {:ok, %File.Stat{type: :other}} ->
        case :gen_tcp.connect({:local, local}, 0, [:local], 1_000) do
          {:ok, s} ->
            :gen_tcp.close(s)
            {:error, "a server is already running on #{path}"}

          {:error, _} ->
            File.rm(local)
        end

      {:ok, _} ->
        {:error, "#{path} exists and is not a socket"}
    end
  end

  defp listen(path) do
    :gen_tcp.listen(0, [
      :binary,
      :local,
      {:ifaddr, {:local, path}},
      {:packet, 4},
      {:active, false},
      {:backlog, 64}
    ])
  end

  # The pause after a failed accept, doubled on each failure in a row up to
  # the last: out of descriptors (emfile, enfile), accept fails at once, and
  # trying again without a pause is a busy loop that floods the log.
  @backoff_ms {50, 1_000}

  defp accept(socket, server, runner, failures \\ 0) do
    case :gen_tcp.accept(socket) do
      {:ok, client} ->
        if failures > 0,
          do: Logger.warning("ringtracer serve: accepting commands again")

        {:ok, pid} = Session.start(client, runner)
        :ok = :gen_tcp.controlling_process(client, pid)
        send(pid, :go)
        accept(socket, server, runner)

      {:error, :closed} ->
        :ok

      {:error, reason} ->
        # one line for a run of failures, not one per try
        if failures == 0,
          do:
            Logger.warning(
              "ringtracer serve: cannot accept a command: #{accept_error(reason)}; " <>
                "trying again, less often, until it can"
            )

        Process.sleep(backoff(failures))
        accept(socket, server, runner, failures + 1)
    end
  end

  # The pause after the `failures`-th failed accept in a row (0 the first).
  defp backoff(failures) do
    {first, last} = @backoff_ms
    min(first * Integer.pow(2, min(failures, 16)), last)
  end

  # No :file.format_error/1 here: out of descriptors, a module not loaded
  # yet (its erl_posix_msg) cannot be loaded.
  defp accept_error(reason) when reason in [:emfile, :enfile],
    do: "too many open files (#{reason})"

  defp accept_error(reason), do: inspect(reason)

  @impl GenServer
  def handle_info({:EXIT, pid, reason}, %{acceptor: pid} = state),
    do: {:stop, reason, state}

  def handle_info(_msg, state), do: {:noreply, state}

  @impl GenServer
  def terminate(_reason, state) do
    :gen_tcp.close(state.socket)
    File.rm(state.local)
    :ok
  end
end
