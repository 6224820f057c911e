defmodule RingTracer.Bench.Network.Remote do
  @moduledoc false
  # What the network benchmark runs on its nodes (`RingTracer.Bench.Network.Lab`),
  # called through each node's standard I/O (`:peer.call/5`), so that the
  # controlling VM never joins their distribution and adds nothing to the
  # traffic being measured.

  alias RingTracer.Bench.Network.Epmd
  alias RingTracer.Cluster.Cookie

  @doc """
  Makes this VM the node `name` (a short name) listening on `ip`, with the
  benchmark's port map (`RingTracer.Bench.Network.Epmd.configure/1`) and
  the cookie in `cookie_file`, then starts `:ring_tracer`.
  """
  @spec boot(String.t(), :inet.ip_address(), Epmd.config(), Path.t()) :: :ok
  def boot(name, ip, epmd, cookie_file) do
    :ok = Epmd.configure(epmd)
    :ok = Application.put_env(:kernel, :inet_dist_use_interface, ip)
    {:ok, _} = Node.start(String.to_atom(name), :shortnames)
    {:ok, cookie} = Cookie.read(cookie_file)
    true = Node.set_cookie(cookie)
    :ok = Application.put_env(:logger, :level, :warning)
    {:ok, _} = Application.ensure_all_started(:ring_tracer)
    :ok
  end

  @doc "Connects this node to each of `nodes` (through the relay)."
  @spec connect([node()]) :: :ok
  def connect(nodes) do
    for n <- nodes, do: true = Node.connect(n)
    :ok
  end

  @doc """
  Round trips to `other`, in microseconds: `n` times `:net_adm.ping/1` on an
  open connection (one request to its net kernel and the answer).
  """
  @spec ping_us(node(), pos_integer()) :: [non_neg_integer()]
  def ping_us(other, n) do
    for _ <- 1..n do
      {us, :pong} = :timer.tc(fn -> :net_adm.ping(other) end)
      us
    end
  end

  @doc """
  This node's distribution traffic so far, summed over its connections:
  packets (one per distribution message, or per fragment of a large one)
  and bytes sent and received, from `:inet.getstat/2` on the sockets.
  """
  @spec counters() :: %{
          send_cnt: non_neg_integer(),
          send_oct: non_neg_integer(),
          recv_cnt: non_neg_integer(),
          recv_oct: non_neg_integer()
        }
  def counters do
    keys = [:send_cnt, :send_oct, :recv_cnt, :recv_oct]
    zero = Map.new(keys, &{&1, 0})

    for {_node, ctrl} <- :erlang.system_info(:dist_ctrl), is_port(ctrl), reduce: zero do
      acc ->
        case :inet.getstat(ctrl, keys) do
          {:ok, stats} ->
            Enum.reduce(stats, acc, fn {k, v}, a -> Map.update!(a, k, &(&1 + v)) end)

          {:error, _} ->
            acc
        end
    end
  end

  @doc """
  Renders `scene` from this node with `opts` and returns what the benchmark
  needs: makespan (to the last atom) and the time until the call returned
  (`wall_us`), the ideal time with `cap` atoms tracing at once, the atom
  and pixel counts, the job's own message counts and the pixels
  (`pixels: true`) or their SHA-256. The scene is loaded once per node
  and path, so that its parsing on this node is not part of any job's
  time.
  """
  @spec render(Path.t(), keyword(), pos_integer(), boolean()) :: {:ok, map()} | {:error, term()}
  def render(path, opts, cap, pixels?) do
    scene = loaded(path)
    t0 = System.monotonic_time(:microsecond)

    case RingTracer.render(scene, opts) do
      {:ok, r} ->
        {:ok,
         %{
           elapsed_us: r.elapsed_us,
           wall_us: System.monotonic_time(:microsecond) - t0,
           pixel_count: r.width * r.height,
           ideal_us: RingTracer.Result.ideal_us(r.atoms, Enum.map(r.children, & &1.speed), cap),
           atoms: length(r.atoms),
           job: RingTracer.Result.per_atom(r),
           nodes: Map.keys(r.nodes),
           sha: :crypto.hash(:sha256, r.pixels),
           pixels: if(pixels?, do: r.pixels)
         }}

      {:error, e} ->
        {:error, e}
    end
  end

  defp loaded(path) do
    key = {__MODULE__, :scene, path}

    case :persistent_term.get(key, nil) do
      nil ->
        {:ok, scene} = RingTracer.Scene.load(path)
        :persistent_term.put(key, scene)
        scene

      scene ->
        scene
    end
  end
end
