defmodule RingTracer.LocalCluster do
  @moduledoc """
  Peer nodes on this machine, with OTP's `:peer`, for the distributed tests
  and the multi-node benchmark: starts epmd, makes this node distributed,
  and starts peers that have this node's code paths and run `:ring_tracer`.
  Each peer stops when its controlling process, or this node, goes. For
  real clusters, start workers with `mix ring_tracer.worker` instead.
  """

  @doc "Makes this node distributed (starting epmd first) unless it already is."
  @spec ensure_distributed() :: :ok
  def ensure_distributed do
    unless Node.alive?() do
      {_, 0} = System.cmd("epmd", ["-daemon"])
      name = :"ring_tracer_test_#{System.unique_integer([:positive])}"
      {:ok, _} = Node.start(name, :shortnames)
    end

    :ok
  end

  @doc """
  Starts a peer node. With `code: true` (default) it gets this node's code
  paths and starts `:ring_tracer`; with `code: false` it is a bare Erlang node.
  Returns `{peer_pid, node}`.
  """
  @spec start(String.t(), keyword()) :: {pid(), node()}
  def start(prefix, opts \\ []) do
    ensure_distributed()
    code? = Keyword.get(opts, :code, true)
    paths = if code?, do: Enum.flat_map(:code.get_path(), &[~c"-pa", &1]), else: []
    name = :"#{prefix}_#{System.unique_integer([:positive])}"
    cookie = Atom.to_charlist(Node.get_cookie())

    {:ok, peer, node} =
      :peer.start(%{name: name, args: [~c"-setcookie", cookie | paths], wait_boot: 30_000})

    if code? do
      :ok = :erpc.call(node, Application, :put_env, [:logger, :level, :warning])
      {:ok, _} = :erpc.call(node, Application, :ensure_all_started, [:ring_tracer])
    end

    {peer, node}
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
