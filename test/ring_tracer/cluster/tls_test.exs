defmodule RingTracer.Cluster.TLSTest do
  # Real OS processes on loopback, every one a node with TLS distribution
  # (or deliberately without), controlled through its standard I/O.
  use ExUnit.Case, async: true

  @moduletag :distributed
  @moduletag timeout: 240_000

  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.TestScenes

  @scene "balls_s2.nff"

  setup_all do
    dir =
      Path.join(System.tmp_dir!(), "rt_tls_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")

    File.mkdir_p!(dir)
    ca = Path.join(dir, "ca")
    other_ca = Path.join(dir, "other_ca")
    tls!(["ca", ca])
    tls!(["ca", other_ca])
    for n <- ["w1", "w2", "render"], do: tls!(["node", ca, Path.join(dir, n), "localhost"])
    tls!(["node", other_ca, Path.join(dir, "stranger"), "localhost"])

    peers =
      for n <- ["w1", "w2", "render", "stranger"],
          into: %{},
          do: {n, Peers.start("tls_#{n}", tls: Path.join(dir, n))}

    # Speaks TLS distribution but presents no certificate.
    {_, no_cert} =
      peers_no_cert =
      Peers.start("tls_nocert", args: ["-proto_dist", "inet_tls"], tls: nil, connection: :stdio)

    # Plain TCP distribution (this node runs TLS: controlled through its standard I/O).
    plain_peer = Peers.start("plain", plain: true)

    on_exit(fn ->
      Enum.each([peers_no_cert, plain_peer | Map.values(peers)], fn {p, _} -> Peers.stop(p) end)
      File.rm_rf!(dir)
    end)

    {:ok,
     peers: peers,
     no_cert: {elem(peers_no_cert, 0), no_cert},
     plain: plain_peer,
     reference: TestScenes.reference(@scene, 64, 48)}
  end

  defp tls!(args) do
    {out, status} =
      System.cmd(Path.expand("bin/ringtracer"), ["tls" | args], stderr_to_stdout: true)

    assert status == 0, out
  end

  defp call({peer, node}, m, f, a), do: Peers.call(peer, node, m, f, a)

  test "a render across two TLS workers is byte-identical to a local one", %{
    peers: peers,
    reference: reference
  } do
    render = peers["render"]
    nodes = [elem(peers["w1"], 1), elem(peers["w2"], 1)]
    assert call(render, RingTracer.Cluster.TLS, :enabled?, [])

    {:ok, result} =
      call(render, RingTracer, :render, [
        TestScenes.path(@scene),
        [nodes: nodes, children: 6, atoms: 4, width: 64, height: 48]
      ])

    assert result.pixels == reference
    assert Enum.sort(Map.keys(result.nodes)) == Enum.sort([elem(render, 1) | nodes])
  end

  test "a node with a certificate from another CA is refused, and the render says why", %{
    peers: peers
  } do
    {_, stranger} = peers["stranger"]

    {:error, error} =
      call(peers["render"], RingTracer, :render, [
        TestScenes.path(@scene),
        [nodes: [stranger], width: 16, height: 16]
      ])

    assert error.reason == :node_unavailable
    assert error.message =~ "cannot connect to node #{stranger}"
    assert error.message =~ "not signed by our CA"
  end

  test "a plain-TCP node is refused both ways", %{peers: peers, plain: {_, plain} = plain_peer} do
    {_, w1} = peers["w1"]

    {:error, error} =
      call(peers["render"], RingTracer, :render, [
        TestScenes.path(@scene),
        [nodes: [plain], width: 16, height: 16]
      ])

    assert error.message =~ "cannot connect to node #{plain}"
    assert error.message =~ "plain TCP"

    refute call(plain_peer, Node, :connect, [w1])
    {:error, error} = call(plain_peer, RingTracer.Cluster, :check, [[w1]])
    assert error.message =~ "over TLS only"
  end

  test "a TLS node without a certificate is refused", %{peers: peers, no_cert: no_cert} do
    {_, w1} = peers["w1"]
    refute call(no_cert, Node, :connect, [w1])
    assert call(peers["w1"], Node, :list, []) |> Enum.all?(&(&1 != elem(no_cert, 1)))
  end
end
