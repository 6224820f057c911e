defmodule RingTracer.Cluster.EpmdTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Cluster.Epmd

  alias RingTracer.Cluster.Epmd

  @header "  sl  local_address                         remote_address                        st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode\n"

  test "IPv6 listeners are read word by word, and only listening sockets on the port count" do
    # ::1 port 4369 listening (uid 1001); 0.0.0.0-style :: on 4369 (uid 0);
    # an established connection to 4369 (state 01), and another port.
    table =
      @header <>
        "   0: 00000000000000000000000001000000:1111 00000000000000000000000000000000:0000 0A 00000000:00000000 00:00000000 00000000  1001        0 1 1 0\n" <>
        "   1: 00000000000000000000000000000000:1111 00000000000000000000000000000000:0000 0A 00000000:00000000 00:00000000 00000000     0        0 2 1 0\n" <>
        "   2: 00000000000000000000000001000000:1111 00000000000000000000000001000000:9C40 01 00000000:00000000 00:00000000 00000000  1001        0 3 1 0\n" <>
        "   3: 00000000000000000000000001000000:1F90 00000000000000000000000000000000:0000 0A 00000000:00000000 00:00000000 00000000  1001        0 4 1 0\n"

    assert Epmd.parse(table, 4369) == [
             %{address: {0, 0, 0, 0, 0, 0, 0, 1}, uid: 1001},
             %{address: {0, 0, 0, 0, 0, 0, 0, 0}, uid: 0}
           ]
  end

  test "another user's listener is foreign; this user's and root's are not" do
    listeners = [
      %{address: {127, 0, 0, 1}, uid: 1001},
      %{address: {127, 0, 0, 1}, uid: 1000},
      %{address: {0, 0, 0, 0}, uid: 0}
    ]

    assert Epmd.foreign(listeners, 1000) == [%{address: {127, 0, 0, 1}, uid: 1001}]
  end

  test "the kernel's tables hold this machine's listening sockets with their owners" do
    {:ok, socket} = :gen_tcp.listen(0, ip: {127, 0, 0, 1})
    {:ok, port} = :inet.port(socket)
    assert Epmd.listeners(port) == [%{address: {127, 0, 0, 1}, uid: Epmd.own_uid()}]
    :gen_tcp.close(socket)
    assert Epmd.listeners(port) == []
  end
end
