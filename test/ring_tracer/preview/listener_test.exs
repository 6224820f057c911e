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
end
