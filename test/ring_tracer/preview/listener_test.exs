defmodule RingTracer.Preview.ListenerTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Preview.Listener

  alias RingTracer.Preview.Listener

  test "a token is 128 random bits, URL-safe, new each time" do
    tokens = for _ <- 1..100, do: Listener.token()
    assert length(Enum.uniq(tokens)) == 100
    assert Enum.all?(tokens, &(&1 =~ ~r/\A[A-Za-z0-9_-]{22}\z/))
  end

  test "a port that cannot be had is said in words, naming it" do
    assert Listener.failure(:eaddrinuse, {127, 0, 0, 1}, 8080) =~
             "port 8080 on 127.0.0.1 is in use"

    assert Listener.failure(:eaddrnotavail, {10, 1, 2, 3}, 0) =~
             "cannot listen on 10.1.2.3: it is not an address of this machine"

    assert Listener.host({0, 0, 0, 0, 0, 0, 0, 1}) == "[::1]"
  end

  defmodule Handler do
    @moduledoc false
    # A server's only module: the checks, then a short page.
    alias RingTracer.Preview.Listener

    def unquote(:do)(m) do
      case Listener.check(m, Listener.data(m), :any) do
        {:ok, _} -> Listener.body("hi", ~c"text/plain", ~c"default-src 'none'")
        {:error, response} -> response
      end
    end
  end

  defp connect(port) do
    {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false], 5_000)
    sock
  end

  # A whole response of the handler (its body "hi" last), however it arrives.
  defp response(sock, acc) do
    if String.ends_with?(acc, "\r\n\r\nhi") do
      acc
    else
      assert {:ok, data} = :gen_tcp.recv(sock, 0, 5_000)
      response(sock, acc <> data)
    end
  end

  defp connections(l), do: length(Supervisor.which_children(l.connections))

  defp await_connections(l, n) do
    assert RingTracer.Test.Wait.eventually(fn -> connections(l) == n end, 10_000),
           "#{connections(l)} connections, not #{n}"
  end

  @tag :tmp_dir
  test "the sweep drops the oldest beyond its bound, never a new one nor one that showed the token",
       %{tmp_dir: dir} do
    # The server is linked, and its stop an exit signal.
    Process.flag(:trap_exit, true)
    token = Listener.token()

    {:ok, l} =
      Listener.start(Handler, token, root: dir, name: ~c"listener-test", max_clients: 100)

    try do
      # One that showed the token, its connection kept alive; then 3 that
      # send nothing.
      owner = connect(l.port)
      :ok = :gen_tcp.send(owner, "GET /#{token}/ HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
      assert "HTTP/1.1 200 " <> _ = response(owner, "")
      old = for _ <- 1..3, do: connect(l.port)
      await_connections(l, 4)

      # Seen for the first time: none dropped, however many.
      seen = Listener.sweep(l, %{}, %{}, 1, 0)
      assert map_size(seen) == 3
      new = for _ <- 1..3, do: connect(l.port)
      await_connections(l, 7)

      # Beyond 1 waiting: the 3 old ones go (the new ones are seen for the
      # first time), then 2 of the new ones; the owner's stays. Within their
      # grace (here a minute), none goes.
      assert Listener.sweep(l, seen, %{}, 1, 60_000) |> map_size() == 6
      await_connections(l, 7)
      seen = Listener.sweep(l, seen, %{}, 1, 0)
      assert map_size(seen) == 3
      await_connections(l, 4)
      for sock <- old, do: assert(:gen_tcp.recv(sock, 0, 5_000) == {:error, :closed})
      seen = Listener.sweep(l, seen, %{}, 1, 0)
      assert map_size(seen) == 1
      # Their processes gone, their sockets are closed.
      await_connections(l, 2)
      assert Enum.count(new, &(:gen_tcp.recv(&1, 0, 1_000) == {:error, :closed})) == 2
      :ok = :gen_tcp.send(owner, "GET /#{token}/ HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
      assert "HTTP/1.1 200 " <> _ = response(owner, "")
    after
      Listener.close(l)
    end
  end
end
