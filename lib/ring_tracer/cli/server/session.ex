defmodule RingTracer.CLI.Server.Session do
  @moduledoc false
  # One client of the resident server (`RingTracer.CLI.Server`): it reads
  # the request, runs the command in a process of its own whose stdout and
  # stderr are the client's, and sends back the exit status.
  #
  # The frames (each a 4-byte big-endian length, then a tag byte and the
  # data), client to server: `C` the caller's folder, `A` an argument (one
  # each, in order), `T` `1` if the client's stderr is a terminal, `U` its
  # umask in octal (the files the command creates get the permissions the
  # client's own would give them), `H` its home (`~` in a path), `G` that is all; `Y` go ahead (after the
  # server's `R`); later `I` interrupt (Ctrl-C) and `K` terminate. Server to
  # client: `R` the server takes the command, `O` bytes for stdout, `E` bytes
  # for stderr, `P` (every second while the command runs) still at work, `X`
  # the exit status (one byte), or `F` alone: boot a VM of your own for this
  # command (a render on other nodes, or a command other than `render`).
  #
  # The command runs only after the client's `Y`: a client that gave up
  # waiting for `R` (a server stopped or busy for a while) has a VM of its
  # own do the command, and never gets a second run from a server that wakes
  # up late. A client has 5 s to send its request, and 5 s more for its
  # `Y`; one that does not is dropped without running anything.

  alias RingTracer.CLI.{Console, Render, Signals}
  alias RingTracer.CLI.Server.Device

  @typedoc "What the client has said so far, and the command once it runs."
  @type t :: %__MODULE__{
          socket: :gen_tcp.socket(),
          cwd: Path.t() | nil,
          args: [String.t()],
          tty?: boolean(),
          umask: non_neg_integer() | nil,
          home: Path.t() | nil,
          command: {pid(), reference()} | nil,
          runner: RingTracer.CLI.Server.runner(),
          phase: :request | :confirm | :running,
          deadline: integer() | nil
        }
  defstruct [
    :socket,
    :cwd,
    :runner,
    :deadline,
    args: [],
    tty?: false,
    umask: nil,
    home: nil,
    command: nil,
    phase: :request
  ]

  # How long a client has to send its request, and then its `Y`.
  @request_ms 5_000
  # How often a running command's client hears from the server.
  @ping_ms 1_000

  # How long a command may take to stop once its client has gone.
  @stop_ms 2_000

  @doc "A session for the accepted `socket`, running its command with `runner`; it starts reading on `:go`."
  @spec start(:gen_tcp.socket(), RingTracer.CLI.Server.runner()) :: {:ok, pid()}
  def start(socket, runner) do
    pid =
      spawn(fn ->
        receive do
          :go ->
            loop(%__MODULE__{socket: socket, runner: runner, deadline: deadline()})
        end
      end)

    {:ok, pid}
  end

  @doc """
  What the server does with a request: run it here, or tell the client to
  boot a VM of its own.

      iex> RingTracer.CLI.Server.Session.served?(["render", "a.nff", "-o", "a.png"])
      true
      iex> RingTracer.CLI.Server.Session.served?(["render", "a.nff", "-o", "a.png", "--nodes", "w1@h"])
      false
      iex> RingTracer.CLI.Server.Session.served?(["worker", "--sname", "w1"])
      false
  """
  @spec served?([String.t()]) :: boolean()
  def served?(["render" | argv]), do: not Render.own_vm?(argv)
  def served?(_args), do: false

  defp deadline, do: System.monotonic_time(:millisecond) + @request_ms

  # while the command runs: until the next `P`
  defp left(%{phase: :running}), do: @ping_ms
  defp left(%{deadline: d}), do: max(d - System.monotonic_time(:millisecond), 0)

  defp loop(state) do
    case :inet.setopts(state.socket, active: :once) do
      :ok -> receive_next(state)
      # the client went before its command ran: nothing to stop
      {:error, _} when state.command == nil -> :gen_tcp.close(state.socket)
      {:error, _} -> gone(state)
    end
  end

  defp receive_next(state) do
    receive do
      {:tcp, _, "Y"} when state.phase == :confirm ->
        run(%{state | phase: :running})

      {:tcp, _, _} when state.phase == :confirm ->
        finish(state, 2)

      {:tcp, _, <<"C", cwd::binary>>} ->
        loop(%{state | cwd: cwd})

      {:tcp, _, <<"A", arg::binary>>} ->
        loop(%{state | args: [arg | state.args]})

      {:tcp, _, <<"H", home::binary>>} ->
        loop(%{state | home: home})

      {:tcp, _, <<"T", flag::binary>>} ->
        loop(%{state | tty?: flag == "1"})

      {:tcp, _, <<"U", umask::binary>>} ->
        case Integer.parse(umask, 8) do
          {mask, ""} when mask in 0..0o777 -> loop(%{state | umask: mask})
          _ -> finish(state, 2)
        end

      {:tcp, _, "G"} when state.phase == :request ->
        take(%{state | args: Enum.reverse(state.args)})

      {:tcp, _, "I"} ->
        loop(interrupt(state, :sigint))

      {:tcp, _, "K"} ->
        loop(interrupt(state, :sigterm))

      {:tcp, _, _other} ->
        finish(state, 2)

      {:tcp_closed, _} ->
        gone(state)

      {:DOWN, ref, _, _, reason} when is_tuple(state.command) and elem(state.command, 1) == ref ->
        status =
          receive do
            {:status, ^ref, status} -> status
          after
            0 ->
              _ =
                :gen_tcp.send(state.socket, [
                  "E",
                  "ringtracer: the command failed: #{inspect(reason)}\n"
                ])

              1
          end

        finish(state, status)
    after
      left(state) ->
        if state.phase == :running do
          # the client's sign that the server is not stopped or wedged
          _ = :gen_tcp.send(state.socket, "P")
          loop(state)
        else
          # a client that does not finish its request in time: dropped unrun
          :gen_tcp.close(state.socket)
        end
    end
  end

  # The request is complete: take it (`R`, then wait for the client's `Y`)
  # or send it to a VM of its own.
  defp take(state) do
    if served?(state.args) and is_binary(state.cwd) do
      case :gen_tcp.send(state.socket, "R") do
        :ok -> loop(%{state | phase: :confirm, deadline: deadline()})
        {:error, _} -> :gen_tcp.close(state.socket)
      end
    else
      _ = :gen_tcp.send(state.socket, "F")
      :gen_tcp.close(state.socket)
    end
  end

  defp run(state) do
    me = self()
    out = Device.start(state.socket, "O", state.tty?, me)
    err = Device.start(state.socket, "E", state.tty?, me)

    console = %Console{
      err: err,
      cwd: state.cwd,
      tty?: state.tty?,
      umask: state.umask,
      home: state.home
    }

    {args, runner} = {state.args, state.runner}

    {pid, ref} =
      spawn_monitor(fn ->
        Process.group_leader(self(), out)
        Console.put(console)
        ref = receive do: ({:ref, ref} -> ref)
        send(me, {:status, ref, runner.(args)})
      end)

    send(pid, {:ref, ref})
    loop(%{state | command: {pid, ref}})
  end

  # The command takes an interrupt as it takes one from the launcher.
  defp interrupt(%{command: {pid, _}} = state, signal) do
    send(pid, {Signals, signal})
    state
  end

  defp interrupt(state, _signal), do: state

  defp finish(state, status) do
    _ = :gen_tcp.send(state.socket, <<"X", status>>)
    :gen_tcp.close(state.socket)
  end

  # The client went away (killed, or a second Ctrl-C): its job is cancelled
  # as on an interrupt, and the command is stopped if it does not end.
  defp gone(%{command: {pid, ref}}) do
    send(pid, {Signals, :sigint})

    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    after
      @stop_ms -> Process.exit(pid, :kill)
    end
  end

  defp gone(_state), do: :ok
end
