defmodule RingTracer.Test.FakeEpmd do
  @moduledoc """
  Another user's epmd, for the security tests: it listens on
  127.0.0.1:4369 (start it, as that user, in a network namespace of the
  test's own, before any real epmd), takes registrations, and answers
  every port query with a relay of its own that forwards to the real node
  and prints what passes through it. Run with
  `erl -noshell -pa ... -s Elixir.RingTracer.Test.FakeEpmd main`; it prints
  `LISTENING`, `REGISTERED NAME PORT` and `DATA ID to|from BASE64` lines.
  """

  @spec main() :: no_return()
  def main do
    {:ok, listen} =
      :gen_tcp.listen(4369, [:binary, ip: {127, 0, 0, 1}, active: false, reuseaddr: true])

    registry = spawn(fn -> registry(%{}) end)
    say("LISTENING")
    accept(listen, registry)
  end

  defp say(line), do: IO.puts(line)

  defp registry(names) do
    receive do
      {:put, name, port} -> registry(Map.put(names, name, port))
      {:get, from} -> send(from, {:names, names}) && registry(names)
    end
  end

  defp names(registry) do
    send(registry, {:get, self()})

    receive do
      {:names, names} -> names
    end
  end

  defp accept(listen, registry) do
    {:ok, socket} = :gen_tcp.accept(listen)
    pid = spawn(fn -> serve(socket, registry) end)
    :ok = :gen_tcp.controlling_process(socket, pid)
    accept(listen, registry)
  end

  defp serve(socket, registry) do
    with {:ok, <<length::16>>} <- :gen_tcp.recv(socket, 2),
         {:ok, request} <- :gen_tcp.recv(socket, length) do
      handle(request, socket, registry)
    end
  end

  # ALIVE2_REQ: the registration lasts as long as its connection.
  defp handle(
         <<120, port::16, _type, _proto, _high::16, _low::16, n::16, name::binary-size(n),
           _::binary>>,
         socket,
         registry
       ) do
    send(registry, {:put, name, port})
    say("REGISTERED #{name} #{port}")
    :ok = :gen_tcp.send(socket, <<118, 0, 7::32>>)
    _ = :gen_tcp.recv(socket, 0)
  end

  # PORT_PLEASE2_REQ: the port of a relay of ours.
  defp handle(<<122, name::binary>>, socket, registry) do
    case names(registry) do
      %{^name => port} ->
        {:ok, relay} = :gen_tcp.listen(0, [:binary, ip: {127, 0, 0, 1}, active: false])
        {:ok, relay_port} = :inet.port(relay)
        pid = spawn(fn -> relay(relay, port) end)
        :ok = :gen_tcp.controlling_process(relay, pid)

        :gen_tcp.send(
          socket,
          <<119, 0, relay_port::16, 77, 0, 6::16, 5::16, byte_size(name)::16, name::binary,
            0::16>>
        )

      _ ->
        :gen_tcp.send(socket, <<119, 1>>)
    end

    :gen_tcp.close(socket)
  end

  # NAMES_REQ
  defp handle(<<110>>, socket, registry) do
    lines = for {name, port} <- names(registry), do: "name #{name} at port #{port}\n"
    :gen_tcp.send(socket, [<<4369::32>> | lines])
    :gen_tcp.close(socket)
  end

  defp handle(_other, socket, _registry), do: :gen_tcp.close(socket)

  defp relay(listen, port) do
    {:ok, client} = :gen_tcp.accept(listen)
    {:ok, server} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false])
    id = System.unique_integer([:positive])
    spawn(fn -> pipe(client, server, "#{id} to") end)
    pipe(server, client, "#{id} from")
  end

  defp pipe(from, to, tag) do
    case :gen_tcp.recv(from, 0) do
      {:ok, data} ->
        say("DATA #{tag} #{Base.encode64(data)}")
        _ = :gen_tcp.send(to, data)
        pipe(from, to, tag)

      {:error, _} ->
        :gen_tcp.close(to)
    end
  end
end
