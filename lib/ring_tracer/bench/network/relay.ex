defmodule RingTracer.Bench.Network.Relay do
  @moduledoc """
  A TCP relay that holds every byte for a one-way delay before passing it
  on: the network benchmark's stand-in for a long link, since this kernel
  has no `netem`.

  It runs in the calling VM, with its sockets in another network namespace
  (gen_tcp's `netns` option: the benchmark's hub). Each route is a
  listener at `{ip, port}` that forwards every connection it accepts to
  `{to_ip, to_port}`. Per direction of a connection one process reads
  what arrives, stamps it with `now + delay` and writes it out when that
  time comes, in order, so the delay does not cut the throughput: a chunk
  waits for its own deadline, not for the chunks before it to be
  delivered. Reading pauses while more than #{div(4_194_304, 1_048_576)} MiB
  wait, so a slow link (the `tbf` limit on the other side) pushes back to
  the sender through TCP.

  The relay ends the TCP connection on each side (it acknowledges data
  itself), so it delays data and not acknowledgements: the delay shows as
  latency, and TCP windows never limit throughput.

  `set_delay/2` changes the delay of every connection, open or future.
  """

  @queue_limit 4_194_304

  @typedoc "A listener `{ip, port}` and where it forwards to."
  @type route ::
          {{:inet.ip_address(), :inet.port_number()}, {:inet.ip_address(), :inet.port_number()}}

  @doc """
  Starts the relay's listeners in the network namespace at `netns` (a
  path such as `/var/run/netns/NAME`). Returns the relay's pid, linked to
  the caller.
  """
  @spec start(Path.t(), [route()], non_neg_integer()) :: {:ok, pid()} | {:error, term()}
  def start(netns, routes, delay_us) do
    caller = self()

    pid =
      spawn_link(fn ->
        delay = :atomics.new(1, signed: false)
        :atomics.put(delay, 1, delay_us)

        listeners =
          Enum.map(routes, fn {{ip, port}, to} ->
            {:gen_tcp.listen(port, [
               :binary,
               ip: ip,
               netns: netns,
               active: false,
               reuseaddr: true,
               nodelay: true,
               backlog: 64
             ]), to}
          end)

        case Enum.find(listeners, &match?({{:error, _}, _}, &1)) do
          nil ->
            owner = self()

            for {{:ok, l}, to} <- listeners do
              spawn_link(fn -> accept(l, to, netns, {owner, delay}) end)
            end

            send(caller, {self(), :ok})
            owner(delay)

          {{:error, reason}, _} ->
            send(caller, {self(), {:error, reason}})
        end
      end)

    receive do
      {^pid, :ok} -> {:ok, pid}
      {^pid, {:error, reason}} -> {:error, reason}
    end
  end

  @doc "Sets the one-way delay, in microseconds, for every byte from now on."
  @spec set_delay(pid(), non_neg_integer()) :: :ok
  def set_delay(relay, delay_us) do
    send(relay, {:set_delay, self(), delay_us})

    receive do
      {^relay, :ok} -> :ok
    end
  end

  @doc "Stops the relay: its listeners and every connection through it."
  @spec stop(pid()) :: :ok
  def stop(relay) do
    ref = Process.monitor(relay)
    Process.unlink(relay)
    Process.exit(relay, :shutdown)

    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    end
  end

  defp owner(delay) do
    receive do
      {:set_delay, from, us} ->
        :atomics.put(delay, 1, us)
        send(from, {self(), :ok})
        owner(delay)
    end
  end

  defp accept(listener, {ip, port} = to, netns, shared) do
    case :gen_tcp.accept(listener) do
      {:ok, inbound} ->
        opts = [:binary, netns: netns, active: false, nodelay: true]

        case :gen_tcp.connect(ip, port, opts, 10_000) do
          {:ok, outbound} ->
            :ok = :inet.setopts(inbound, nodelay: true)
            start_pumps(inbound, outbound, shared)

          {:error, _} ->
            :gen_tcp.close(inbound)
        end

        accept(listener, to, netns, shared)

      {:error, :closed} ->
        :ok
    end
  end

  # Two processes per connection, linked to each other (when one side
  # closes, both go), each owning the socket it reads and watching the
  # relay's owner (when it stops, every connection goes).
  defp start_pumps(a, b, shared) do
    parent = self()

    one =
      spawn(fn ->
        receive do: ({:go, ^parent} -> pump(a, b, shared))
      end)

    other =
      spawn(fn ->
        Process.link(one)
        receive do: ({:go, ^parent} -> pump(b, a, shared))
      end)

    :ok = :gen_tcp.controlling_process(a, one)
    :ok = :gen_tcp.controlling_process(b, other)
    send(one, {:go, parent})
    send(other, {:go, parent})
  end

  defp pump(from, to, {owner, delay}) do
    Process.monitor(owner)
    _ = :inet.setopts(from, active: :once)
    loop(%{from: from, to: to, delay: delay, queue: :queue.new(), bytes: 0, reading: true})
  end

  defp loop(s) do
    receive do
      {:tcp, _, data} ->
        s |> arrive(data) |> resume() |> loop()

      {:timeout, _, :due} ->
        s |> deliver() |> resume() |> loop()

      {:tcp_closed, _} ->
        finish(s)

      {:tcp_error, _, _} ->
        finish(s)

      {:DOWN, _, :process, _, _} ->
        exit(:shutdown)
    end
  end

  defp arrive(s, data) do
    s = %{s | reading: false}

    case :atomics.get(s.delay, 1) do
      0 when s.bytes == 0 ->
        write(s, data)
        s

      us ->
        was_empty = s.bytes == 0
        due = now() + us
        s = %{s | queue: :queue.in({due, data}, s.queue), bytes: s.bytes + byte_size(data)}
        if was_empty, do: arm(due)
        s
    end
  end

  defp deliver(s) do
    t = now()

    case :queue.peek(s.queue) do
      {:value, {due, data}} when due <= t ->
        write(s, data)
        deliver(%{s | queue: :queue.drop(s.queue), bytes: s.bytes - byte_size(data)})

      {:value, {due, _}} ->
        arm(due)
        s

      :empty ->
        s
    end
  end

  defp resume(%{reading: false, bytes: bytes} = s) when bytes < @queue_limit do
    _ = :inet.setopts(s.from, active: :once)
    %{s | reading: true}
  end

  defp resume(s), do: s

  # The sending side closed: what it sent still arrives, each chunk at its
  # time; then both ends close (the linked partner goes too).
  defp finish(s) do
    Enum.each(:queue.to_list(s.queue), fn {due, data} ->
      wait = due - now()
      if wait > 0, do: Process.sleep(div(wait + 999, 1000))
      write(s, data)
    end)

    :gen_tcp.close(s.to)
    exit(:closed)
  end

  defp write(s, data) do
    case :gen_tcp.send(s.to, data) do
      :ok -> :ok
      {:error, _} -> exit(:closed)
    end
  end

  defp arm(due_us), do: :erlang.start_timer(div(due_us + 999, 1000), self(), :due, abs: true)

  defp now, do: System.monotonic_time(:microsecond)
end
