defmodule RingTracer.LocalCluster do
  @moduledoc false
  # Peer nodes on this machine, with OTP's `:peer`, for the distributed tests
  # and the multi-node benchmark: makes this node distributed
  # (`RingTracer.Cluster.Distribution`: loopback, epmd on loopback) and starts
  # peers, each a real OS process, that have this node's code paths and run
  # `:ring_tracer`. Peers listen on 127.0.0.1 and live on the host
  # `localhost`; they read the same cookie file as this node
  # (`~/.erlang.cookie`: nothing secret on their command lines). Each peer
  # stops when its controlling process, or this node, goes. For real
  # clusters, start workers with `ringtracer worker` instead.
  #
  # Distribution runs over TLS with mutual authentication: this node must
  # have been booted with it (`bin/ringtracer mix ...` boots Mix's VMs with
  # the user's own certificates), and peers get the same certificates.

  alias RingTracer.Cluster.{Distribution, TLS}

  @join_ms 60_000

  @doc """
  Makes this node distributed (starting epmd first) unless it already is;
  raises `RingTracer.Error` when it cannot (a VM booted without TLS).
  """
  @spec ensure_distributed() :: :ok
  def ensure_distributed do
    _ = Distribution.start!(generate: true)
    :ok
  rescue
    # Another process of this VM (a test beside) made it distributed first.
    error in RingTracer.Error -> if Node.alive?(), do: :ok, else: reraise(error, __STACKTRACE__)
  end

  @doc """
  Starts a peer node.

  ## Options

    * `:code` — with `true` (default) the peer gets this node's code paths
      and starts `:ring_tracer`; with `false` it is a bare Erlang node
    * `:tls` — a TLS folder (`RingTracer.Cluster.TLS`) for the peer
      (default: this node's). With another folder than this node's, or
      `nil` (no certificates), this node cannot talk to it over
      distribution, so it is controlled through its standard input and
      output (`call/4`), and this node need not be distributed
    * `:plain` — `true`: the peer runs plain TCP distribution, controlled
      through its standard I/O (for tests of refusals)
    * `:connection` — `:stdio` to control the peer through its standard I/O
      (for a peer whose distribution this node cannot join)
    * `:args` — more VM arguments (strings)
    * `:name` — the peer's node name (default: `prefix` made unique), for
      a node that must come back under the same name (a farm's head)

  Returns `{peer_pid, node}`.
  """
  @spec start(String.t(), keyword()) :: {pid(), node()}
  def start(prefix, opts \\ []) do
    code? = Keyword.get(opts, :code, true)
    own = if TLS.enabled?(), do: TLS.booted_dir()

    tls =
      cond do
        opts[:plain] -> nil
        Keyword.has_key?(opts, :tls) -> opts[:tls]
        true -> own
      end

    stdio? =
      opts[:connection] == :stdio or opts[:plain] == true or
        (Keyword.has_key?(opts, :tls) and tls != own)

    unless stdio?, do: ensure_distributed()
    paths = if code?, do: Enum.flat_map(:code.get_path(), &[~c"-pa", &1]), else: []
    name = opts[:name] || String.to_atom(Distribution.unique_name(prefix))

    args =
      [~c"-kernel", ~c"inet_dist_use_interface", ~c"{127,0,0,1}"] ++
        Enum.map(if(tls, do: TLS.vm_args(tls), else: []), &String.to_charlist/1) ++
        Enum.map(Keyword.get(opts, :args, []), &String.to_charlist/1) ++
        [~c"-kernel", ~c"prevent_overlapping_partitions", ~c"false"] ++ paths

    # Every peer boots controlled through its standard I/O, and one this node
    # can talk to is then joined over distribution, with a deadline: a peer
    # booted to report over distribution (OTP's `-origin`) does so in a call
    # of 5 s, which a loaded machine once missed (the peer halted, and this
    # node waited out the whole boot deadline). A boot takes about a second,
    # here as with four busy loops beside it.
    options = %{
      name: name,
      host: ~c"localhost",
      args: args,
      wait_boot: 120_000,
      connection: :standard_io
    }

    {:ok, peer, node} = :peer.start(options)
    unless stdio?, do: join!(node, System.monotonic_time(:millisecond) + @join_ms)

    if code? do
      :ok = call(peer, node, Application, :put_env, [:logger, :level, :warning])
      {:ok, _} = call(peer, node, Application, :ensure_all_started, [:ring_tracer])
    end

    {peer, node}
  end

  # Connects to a booted peer, again until the deadline: a connection's set-up
  # (TLS on both sides) can fail on a loaded machine and succeed a moment later.
  defp join!(node, deadline) do
    cond do
      Node.connect(node) == true ->
        :ok

      System.monotonic_time(:millisecond) < deadline ->
        Process.sleep(100)
        join!(node, deadline)

      true ->
        raise "could not connect to the peer #{node} within #{@join_ms} ms"
    end
  end

  @doc "Calls `m.f(a...)` on a peer, over distribution or its standard I/O."
  @spec call(pid(), node(), module(), atom(), [term()]) :: term()
  def call(peer, node, m, f, a) do
    if Node.alive?() and node in Node.list(),
      do: :erpc.call(node, m, f, a, 60_000),
      else: :peer.call(peer, m, f, a, 60_000)
  end

  @doc "Stops a peer (and its node) if it is still running."
  @spec stop(pid()) :: :ok
  def stop(peer) do
    if Process.alive?(peer), do: :peer.stop(peer)
    :ok
  catch
    :exit, _ -> :ok
  end
end
