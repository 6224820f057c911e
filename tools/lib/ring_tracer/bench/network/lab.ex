defmodule RingTracer.Bench.Network.Lab do
  @moduledoc false
  # A small network of RingTracer nodes in Linux network namespaces, for
  # the network benchmark (`RingTracer.Bench.Network`). Needs root (or
  # CAP_NET_ADMIN and CAP_SYS_ADMIN), `ip` and `tc`.
  #
  #     node 0 (the parent)   node 1 .. node k (workers)
  #         eth0                  eth0
  #          |  veth, tbf          |  veth, tbf
  #         h0 ------ hub ------- h1 .. hk
  #                (the relay)
  #
  # Every node is an `erl` in a namespace of its own, joined by a veth pair
  # to one hub namespace. Both ends of each veth get a `tbf` bandwidth limit
  # (`rate`). No node can reach another directly: the only addresses a node
  # knows are its own and the hub's end of its link, where the delaying
  # relay (`RingTracer.Bench.Network.Relay`, an OS process in the hub)
  # listens for each other node and forwards to it. The nodes' port
  # mapper (`RingTracer.Bench.Network.Epmd`) points every node name at the
  # relay, so every distribution connection, parent to worker and worker to
  # worker, crosses two rate-limited links and one delay.
  #
  # This VM controls the nodes through their standard I/O (`:peer`'s
  # `:standard_io` connection) and never joins their distribution. The
  # cookie is a fresh random one in a private file (mode 0600) that the
  # nodes read after they start; nothing secret is on a command line.
  #
  # Names hold this VM's OS process id and random bytes, so runs in
  # parallel cannot collide: namespaces `rtnet-PID-ID-hub` and
  # `rtnet-PID-ID-I`, nodes `rtnet_ID_p@rtnet` and `rtnet_ID_wI@rtnet`;
  # interfaces and addresses (10.77.I.1 at the hub, 10.77.I.2 at node I)
  # exist only inside the run's own namespaces. `stop/1` removes
  # everything (nodes, relay, namespaces, and with them the veths), and
  # `with_lab/2` calls it also when the work fails. A run whose VM was
  # killed leaves namespaces whose PID no longer runs; the next `start/1`
  # removes those.

  alias RingTracer.Bench.Network.{Relay, Remote}
  alias RingTracer.Cluster.Cookie

  @port_base 9100
  @netns_dir "/var/run/netns"

  defstruct [:id, :hub, :relay, :dir, :rate, :nodes, :workers, :parent]

  @typedoc "One node: its name, namespace, address, port and controlling `:peer`."
  @type lab_node :: %{
          index: non_neg_integer(),
          name: node(),
          ns: String.t(),
          ip: :inet.ip_address(),
          port: :inet.port_number(),
          peer: pid() | nil,
          os_pid: non_neg_integer() | nil
        }

  @type t :: %__MODULE__{
          id: String.t(),
          hub: String.t(),
          relay: Relay.t() | nil,
          dir: Path.t() | nil,
          rate: String.t(),
          nodes: [lab_node()],
          workers: [node()],
          parent: lab_node()
        }

  @doc """
  Whether network namespaces can be made here: tries to create one (and
  removes it). `:ok`, or `{:error, why}`.
  """
  @spec probe() :: :ok | {:error, String.t()}
  def probe do
    ns = "rtnet-#{System.pid()}-#{random_id()}-probe"

    cond do
      System.find_executable("ip") == nil ->
        {:error, "the `ip` command (iproute2) is not installed"}

      System.find_executable("tc") == nil ->
        {:error, "the `tc` command (iproute2) is not installed"}

      true ->
        case System.cmd("ip", ["netns", "add", ns], stderr_to_stdout: true) do
          {_, 0} ->
            System.cmd("ip", ["netns", "del", ns], stderr_to_stdout: true)
            :ok

          {out, _} ->
            {:error, "cannot create a network namespace (ip netns add): #{String.trim(out)}"}
        end
    end
  end

  @doc """
  Runs `fun.(lab)` on a lab started with `opts` (see `start/1`) and removes
  the lab afterwards, also when `fun` raises or exits.
  """
  @spec with_lab(keyword(), (t() -> result)) :: result when result: term()
  def with_lab(opts, fun) do
    lab = start(opts)

    try do
      fun.(lab)
    after
      stop(lab)
    end
  end

  @doc """
  Builds the lab and starts its nodes, all distributed and connected to
  each other. Raises (after removing whatever it had made) when a step
  fails.

  ## Options

    * `:workers` — worker nodes (default 2)
    * `:rate` — each link's `tbf` rate, in `tc`'s units (default `"100mbit"`)
    * `:delay_ms` — the relay's one-way delay to start with (default 0)
    * `:dirty_cpu` — dirty CPU schedulers on each worker (default 1: with
      two workers, as many atoms trace at once as this machine has cores)
  """
  @spec start(keyword()) :: t()
  def start(opts) do
    # Built (if it is stale) before anything is made.
    _ = Relay.executable!()
    sweep_stale()
    workers = Keyword.get(opts, :workers, 2)
    id = random_id()
    prefix = "rtnet-#{System.pid()}-#{id}"

    nodes =
      for i <- 0..workers do
        label = if i == 0, do: "p", else: "w#{i}"

        %{
          index: i,
          name: :"rtnet_#{id}_#{label}@rtnet",
          ns: "#{prefix}-#{i}",
          ip: {10, 77, i, 2},
          port: @port_base + i,
          peer: nil,
          os_pid: nil
        }
      end

    lab = %__MODULE__{
      id: id,
      hub: "#{prefix}-hub",
      rate: Keyword.get(opts, :rate, "100mbit"),
      nodes: nodes,
      parent: hd(nodes),
      workers: nodes |> tl() |> Enum.map(& &1.name)
    }

    # Each step records what it made in `lab` before the next one, so that
    # `stop/1` after a failure removes exactly this run's resources.
    Process.put({__MODULE__, id}, lab)

    try do
      build(lab, opts)
    rescue
      e ->
        stop(Process.get({__MODULE__, id}))
        reraise e, __STACKTRACE__
    catch
      kind, reason ->
        stop(Process.get({__MODULE__, id}))
        :erlang.raise(kind, reason, __STACKTRACE__)
    after
      Process.delete({__MODULE__, id})
    end
  end

  defp build(lab, opts) do
    ip!(["netns", "add", lab.hub])
    ip!(["-n", lab.hub, "link", "set", "lo", "up"])
    burst = burst(lab.rate)

    for n <- lab.nodes do
      i = n.index
      ip!(["netns", "add", n.ns])
      ip!(["-n", n.ns, "link", "set", "lo", "up"])

      ip!(~w(link add h#{i} netns #{lab.hub} type veth peer name eth0 netns #{n.ns}))

      ip!(["-n", lab.hub, "addr", "add", "10.77.#{i}.1/24", "dev", "h#{i}"])
      ip!(["-n", n.ns, "addr", "add", "10.77.#{i}.2/24", "dev", "eth0"])
      ip!(["-n", lab.hub, "link", "set", "h#{i}", "up"])
      ip!(["-n", n.ns, "link", "set", "eth0", "up"])

      for {ns, dev} <- [{lab.hub, "h#{i}"}, {n.ns, "eth0"}] do
        cmd!("tc", ~w(-n #{ns} qdisc add dev #{dev} root tbf rate #{lab.rate}
          burst #{burst} latency 100ms))
      end
    end

    # The relay: on the hub's end of link i, one listener per other node j,
    # at j's port, forwarding to j's own address.
    routes =
      for a <- lab.nodes, b <- lab.nodes, a.index != b.index do
        {{{10, 77, a.index, 1}, b.port}, {b.ip, b.port}}
      end

    delay_us = round(Keyword.get(opts, :delay_ms, 0) * 1000)

    relay =
      case Relay.start(lab.hub, routes, delay_us) do
        {:ok, relay} -> relay
        {:error, reason} -> raise "the relay could not start in #{lab.hub}: #{reason}"
      end

    lab = remember(%{lab | relay: relay})

    dir = RingTracer.Bench.private_tmp_dir!("ringtracer-net-#{lab.id}")
    lab = remember(%{lab | dir: dir})
    cookie = Path.join(dir, ".erlang.cookie")
    {:ok, _} = Cookie.create(cookie)

    dirty = Keyword.get(opts, :dirty_cpu, 1)

    lab =
      Enum.reduce(lab.nodes, lab, fn n, lab ->
        args = if n.index == 0, do: [], else: ["+SDcpu", "#{dirty}:#{dirty}"]
        {peer, os_pid} = start_vm(n, dir, args)
        nodes = replace(lab.nodes, %{n | peer: peer, os_pid: os_pid})
        remember(%{lab | nodes: nodes, parent: hd(nodes)})
      end)

    nodes = lab.nodes

    for n <- nodes do
      epmd = %{
        port: n.port,
        routes:
          for(
            m <- nodes,
            m.index != n.index,
            into: %{},
            do: {short(m.name), {{10, 77, n.index, 1}, m.port}}
          )
      }

      :ok = call(n, Remote, :boot, [Atom.to_string(n.name), n.ip, epmd, cookie])
    end

    # The parent connects to every worker, and each worker to the workers
    # after it: a full mesh before anything is measured.
    for {n, k} <- Enum.with_index(nodes) do
      others = nodes |> Enum.drop(k + 1) |> Enum.map(& &1.name)
      :ok = call(n, Remote, :connect, [others])
    end

    lab
  end

  defp remember(lab) do
    Process.put({__MODULE__, lab.id}, lab)
    lab
  end

  defp replace(nodes, n), do: Enum.map(nodes, &if(&1.index == n.index, do: n, else: &1))

  defp short(name), do: name |> Atom.to_string() |> String.split("@") |> hd()

  # An `erl` in the node's namespace, controlled through its standard I/O,
  # with this VM's code paths; HOME is the run's private folder, so the
  # only cookie file the node can find is the run's.
  defp start_vm(n, dir, extra) do
    erl = System.find_executable("erl") || raise "erl not found"
    ip = System.find_executable("ip")
    paths = Enum.flat_map(:code.get_path(), &[~c"-pa", &1])

    args =
      Enum.map(
        ["-epmd_module", "Elixir.RingTracer.Bench.Network.Epmd", "-connect_all", "false"] ++
          extra,
        &String.to_charlist/1
      ) ++ paths

    {:ok, peer, _nonode} =
      :peer.start_link(%{
        exec:
          {String.to_charlist(ip), Enum.map(["netns", "exec", n.ns, erl], &String.to_charlist/1)},
        connection: :standard_io,
        args: args,
        env: [{~c"HOME", String.to_charlist(dir)}],
        wait_boot: 60_000
      })

    os_pid = :peer.call(peer, :os, :getpid, [], 10_000) |> List.to_integer()
    {peer, os_pid}
  end

  @doc "Calls `m.f(a...)` on one of the lab's nodes, through its standard I/O."
  @spec call(lab_node(), module(), atom(), [term()], timeout()) :: term()
  def call(n, m, f, a, timeout \\ 600_000), do: :peer.call(n.peer, m, f, a, timeout)

  @doc """
  Sets every link's `tbf` rate (both ends of each veth), in `tc`'s units,
  e.g. `"100mbit"`.
  """
  @spec set_rate(t(), String.t()) :: t()
  def set_rate(lab, rate) do
    burst = burst(rate)

    for n <- lab.nodes, {ns, dev} <- [{lab.hub, "h#{n.index}"}, {n.ns, "eth0"}] do
      cmd!("tc", ~w(-n #{ns} qdisc change dev #{dev} root tbf rate #{rate}
        burst #{burst} latency 100ms))
    end

    %{lab | rate: rate}
  end

  @doc "Sets the relay's one-way delay, in milliseconds."
  @spec set_delay(t(), number()) :: :ok
  def set_delay(lab, ms), do: Relay.set_delay(lab.relay, round(ms * 1000))

  @doc """
  Round trips from the parent to each worker, in milliseconds (the median of
  `n` pings each, `:net_adm.ping/1` over the open connection).
  """
  @spec rtt_ms(t(), pos_integer()) :: %{node() => float()}
  def rtt_ms(lab, n \\ 7) do
    Map.new(lab.workers, fn w ->
      # Three pings first, not counted: the first after a pause waits for
      # sleeping schedulers on three VMs.
      samples = lab.parent |> call(Remote, :ping_us, [w, n + 3]) |> Enum.drop(3)
      {w, Enum.at(Enum.sort(samples), div(n, 2)) / 1000}
    end)
  end

  @doc """
  The traffic counters of every node: distribution packets and bytes
  (`RingTracer.Bench.Network.Remote.counters/0`), and the bytes of its link
  as the hub sees them (`link_rx`: sent by the node, `link_tx`: sent to it;
  TCP/IP headers and acknowledgements included).
  """
  @spec counters(t()) :: %{node() => map()}
  def counters(lab) do
    links = link_bytes(lab)

    Map.new(lab.nodes, fn n ->
      {rx, tx} = Map.fetch!(links, "h#{n.index}")
      {n.name, Map.merge(call(n, Remote, :counters, []), %{link_rx: rx, link_tx: tx})}
    end)
  end

  defp link_bytes(lab) do
    {out, 0} = cmd!("ip", ["netns", "exec", lab.hub, "cat", "/proc/net/dev"])

    for line <- String.split(out, "\n"),
        [dev, rest] <- [String.split(line, ":", parts: 2)],
        fields = String.split(rest),
        length(fields) >= 16,
        into: %{} do
      {String.trim(dev),
       {String.to_integer(Enum.at(fields, 0)), String.to_integer(Enum.at(fields, 8))}}
    end
  end

  @doc """
  Removes the lab: stops the nodes and the relay, kills any process left in
  its namespaces (by PID: they are this run's) and deletes the namespaces,
  which deletes their veths. Safe to call on a lab that was only partly
  built.
  """
  @spec stop(t() | nil) :: :ok
  def stop(nil), do: :ok

  def stop(%__MODULE__{} = lab) do
    for %{peer: peer} <- lab.nodes, is_pid(peer) do
      try do
        :peer.stop(peer)
      catch
        _, _ -> :ok
      end
    end

    if lab.relay, do: Relay.stop(lab.relay)
    Enum.each([lab.hub | Enum.map(lab.nodes, & &1.ns)], &remove_netns/1)
    if lab.dir, do: File.rm_rf(lab.dir)
    :ok
  end

  defp remove_netns(ns) do
    if File.exists?(Path.join(@netns_dir, ns)) do
      kill_all(ns, 20)
      System.cmd("ip", ["netns", "del", ns], stderr_to_stdout: true)
    end

    :ok
  end

  # Every process still in the namespace, by PID, until none is left.
  defp kill_all(ns, tries) do
    case System.cmd("ip", ["netns", "pids", ns], stderr_to_stdout: true) do
      {out, 0} ->
        pids = String.split(out)

        if pids != [] and tries > 0 do
          System.cmd("kill", ["-KILL" | pids], stderr_to_stdout: true)
          Process.sleep(50)
          kill_all(ns, tries - 1)
        end

      _ ->
        :ok
    end
  end

  # Namespaces of earlier runs whose VM no longer runs (it was killed before
  # it could clean up).
  defp sweep_stale do
    case System.cmd("ip", ["netns", "list"], stderr_to_stdout: true) do
      {out, 0} ->
        for line <- String.split(out, "\n"),
            [_, ns, pid] <- [Regex.run(~r/^(rtnet-(\d+)-[0-9a-f]+-\w+)/, line)],
            pid != System.pid(),
            not File.exists?("/proc/#{pid}"),
            do: remove_netns(ns)

        :ok

      _ ->
        :ok
    end
  end

  # tbf needs a bucket of at least rate / HZ; 10 ms worth of the rate, and
  # at least 64 KiB, is enough for any kernel HZ.
  defp burst(rate) do
    bytes = div(rate_bps(rate), 800)
    "#{max(bytes, 65_536)}b"
  end

  @doc """
  A `tc` rate in bits per second.

      iex> RingTracer.Bench.Network.Lab.rate_bps("100mbit")
      100000000
      iex> RingTracer.Bench.Network.Lab.rate_bps("1gbit")
      1000000000
  """
  @spec rate_bps(String.t()) :: pos_integer()
  def rate_bps(rate) do
    case Regex.run(~r/^(\d+)(kbit|mbit|gbit|bit)?$/, rate) do
      [_, n] ->
        String.to_integer(n)

      [_, n, unit] ->
        String.to_integer(n) *
          %{"bit" => 1, "kbit" => 1000, "mbit" => 1_000_000, "gbit" => 1_000_000_000}[unit]

      nil ->
        raise ArgumentError, "a rate such as 100mbit or 1gbit, got: #{inspect(rate)}"
    end
  end

  defp ip!(args), do: cmd!("ip", args)

  defp cmd!(cmd, args) do
    case System.cmd(cmd, args, stderr_to_stdout: true) do
      {out, 0} ->
        {out, 0}

      {out, status} ->
        raise "#{cmd} #{Enum.join(args, " ")} failed (#{status}): #{String.trim(out)}"
    end
  end

  defp random_id, do: Base.encode16(:crypto.strong_rand_bytes(3), case: :lower)
end
