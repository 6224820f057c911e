defmodule RingTracer.Bench.Network.Relay do
  @moduledoc false
  # The network benchmark's stand-in for long links, since this kernel has no
  # `netem`: `ringtracer-relay` (the crate `native/relay`, std-only Rust), a
  # TCP relay that holds every byte for a one-way delay before passing it on.
  #
  # It runs as an OS process in the lab's hub namespace (`ip netns exec`),
  # controlled through a port: `set_delay/2` changes the delay of every
  # connection, open or future, and closing the port (`stop/1`, or this VM
  # going) ends it. Each route is a listener that forwards every connection
  # to one target. A thread per direction writes each chunk out at its
  # arrival time plus the delay (the OS sleeps with sub-millisecond
  # precision, which BEAM timers, whole milliseconds and late by one or
  # two, do not have); the delay does not cut the throughput, and a full
  # queue pushes back on the sender through TCP. The relay ends TCP on both
  # sides, so it delays data, not acknowledgements.
  #
  # The binary is built with cargo (`cargo build --release -p
  # ring_tracer_relay` in `native/`) when `executable!/0` is first asked for
  # it; cargo rebuilds only when its sources changed.

  @typedoc "A route: a listener `{ip, port}` and the `{ip, port}` it forwards to."
  @type route ::
          {{:inet.ip_address(), :inet.port_number()}, {:inet.ip_address(), :inet.port_number()}}

  @type t :: %{port: port(), os_pid: non_neg_integer()}

  @doc "The relay's executable, built first (cargo decides whether it is stale)."
  @spec executable!() :: Path.t()
  def executable! do
    native = Path.join(File.cwd!(), "native")
    bin = Path.join([native, "target", "release", "ringtracer-relay"])
    cargo = System.find_executable("cargo") || Path.expand("~/.cargo/bin/cargo")

    cond do
      File.exists?(Path.join(native, "relay/Cargo.toml")) and File.exists?(cargo) ->
        case System.cmd(cargo, ~w(build --release -q -p ring_tracer_relay),
               cd: native,
               stderr_to_stdout: true
             ) do
          {_, 0} -> bin
          {out, status} -> raise "building ringtracer-relay failed (#{status}): #{out}"
        end

      File.exists?(bin) ->
        bin

      true ->
        raise "ringtracer-relay not found: run from the RingTracer checkout, with cargo installed"
    end
  end

  @doc """
  Starts the relay in the network namespace `netns` (a name from `ip netns
  list`) with `routes` and a first delay in microseconds. The port is owned
  by the caller.
  """
  @spec start(String.t(), [route()], non_neg_integer()) :: {:ok, t()} | {:error, String.t()}
  def start(netns, routes, delay_us) do
    exe = executable!()
    ip = System.find_executable("ip")

    args =
      ["netns", "exec", netns, exe] ++
        for {{lip, lport}, {tip, tport}} <- routes do
          "#{:inet.ntoa(lip)}:#{lport}=#{:inet.ntoa(tip)}:#{tport}"
        end

    port =
      Port.open({:spawn_executable, ip}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        {:line, 1024},
        args: args
      ])

    {:os_pid, os_pid} = Port.info(port, :os_pid)
    relay = %{port: port, os_pid: os_pid}

    case answer(port, 10_000) do
      "ready" ->
        :ok = set_delay(relay, delay_us)
        {:ok, relay}

      other ->
        stop(relay)
        {:error, "ringtracer-relay did not start: #{other}"}
    end
  end

  @doc "Sets the one-way delay, in microseconds, for every byte read from now on."
  @spec set_delay(t(), non_neg_integer()) :: :ok
  def set_delay(%{port: port}, delay_us) do
    true = Port.command(port, "delay #{delay_us}\n")
    "ok" = answer(port, 5_000)
    :ok
  end

  @doc "Stops the relay: its listeners and every connection through it."
  @spec stop(t()) :: :ok
  def stop(%{port: port}) do
    # Its input closed, it exits by itself (the lab then kills whatever is
    # left in its namespace).
    try do
      Port.close(port)
    rescue
      ArgumentError -> :ok
    end

    :ok
  end

  defp answer(port, timeout) do
    receive do
      {^port, {:data, {:eol, line}}} -> line
      {^port, {:exit_status, status}} -> "exited with status #{status}"
    after
      timeout -> "no answer in #{timeout} ms"
    end
  end
end
