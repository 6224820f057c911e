defmodule RingTracer.Cluster.Distribution do
  @moduledoc false
  # Makes this VM a distributed node at run time, safely by default.
  #
  #   * **Loopback by default.** The distribution listener binds to
  #     127.0.0.1, and epmd (started here when none runs) to 127.0.0.1 too,
  #     unless `listen:` names another address; `ports:` fixes the
  #     listener's port range for firewalls. On loopback, short names get
  #     the host `localhost` (`w1` becomes `w1@localhost`), which always
  #     resolves to the address the node listens on.
  #   * **No cookie on the command line.** The cookie comes from a file
  #     (`cookie_file:`, default `~/.erlang.cookie`) that only its owner can
  #     read (`RingTracer.Cluster.Cookie`), and is set after the node has
  #     started, so `ps` never shows it.
  #   * **Mutual TLS, or nothing, by default.** Distribution runs over TLS
  #     with mutual authentication (`RingTracer.Cluster.TLS`), chosen when
  #     the VM boots: the launcher boots every node with the certificates
  #     of `--tls DIR` or, without it, with the user's own private CA and
  #     node certificate (made on first use). Here it is checked that the
  #     VM was booted so. Plain TCP distribution, which whoever answers on
  #     port 4369 can read and alter, needs `insecure_plain: true`.
  #   * **epmd's owner.** An epmd (port 4369) that belongs to another user
  #     (the kernel's socket tables say whose) is warned about; with plain
  #     distribution it is refused unless `allow_foreign_epmd: true`.
  #   * **Unique names.** A made-up name holds the OS process id and random
  #     bytes; a name already registered with epmd is a clear error.
  #
  # A VM that is already distributed (`elixir --sname X -S mix ...`) is used
  # as it is, apart from the cookie when `cookie_file:` is given.
  #
  # ## Options
  #
  #   * `:sname` — a short name (`w1`, or `w1@host`)
  #   * `:name` — a long name (`w1@host.example`)
  #   * `:generate` — make up a short name when neither is given (default false)
  #   * `:cookie_file` — the cookie file (default `~/.erlang.cookie`)
  #   * `:listen` — the address to listen on, e.g. `"10.0.0.5"` or `"0.0.0.0"`
  #     (default `"127.0.0.1"`)
  #   * `:ports` — `{min, max}` ports of the distribution listener (default:
  #     any free port)
  #   * `:tls` — the node's TLS folder (`RingTracer.Cluster.TLS`); without
  #     it, the folder the VM was booted with
  #   * `:insecure_plain` — plain TCP distribution instead of TLS: anyone
  #     who answers on port 4369, or sits on the network, can read and
  #     alter everything the nodes say, and so run code on them
  #   * `:allow_foreign_epmd` — with `:insecure_plain`, go on even when epmd
  #     belongs to another user

  alias RingTracer.CLI.Console
  alias RingTracer.Cluster.{Cookie, Epmd, TLS}
  alias RingTracer.Error

  @loopback {127, 0, 0, 1}

  @doc """
  Starts distribution as `opts` say. Returns this node's name.

      iex> RingTracer.Cluster.Distribution.start(cookie: "secret")
      {:error, %RingTracer.Error{reason: :cookie, message: "--cookie puts the secret on the command line, where every user of this machine can read it (/proc/PID/cmdline); put it in a file only you can read and give --cookie-file PATH (create one with: ringtracer cookie PATH)"}}
  """
  @spec start(keyword()) :: {:ok, node()} | {:error, Error.t()}
  def start(opts) do
    with :ok <- refuse_cookie(opts),
         {:ok, listen} <- listen_address(opts[:listen]),
         {:ok, ports} <- ports(opts[:ports]),
         {:ok, transport} <- transport(opts),
         {:ok, cookie} <- cookie(opts[:cookie_file]) do
      if transport == :tls, do: TLS.quiet_ssl()

      if Node.alive?() do
        set_cookie(cookie)
        {:ok, node()}
      else
        with {:ok, name, type} <- node_name(opts, listen),
             :ok <- configure_listener(listen, ports),
             :ok <- ensure_epmd(listen, transport, opts),
             :ok <- free_name(name),
             :ok <- start_node(name, type) do
          set_cookie(cookie)
          {:ok, node()}
        end
      end
    end
  end

  @doc "Like `start/1`, but raises `RingTracer.Error`."
  @spec start!(keyword()) :: node()
  def start!(opts) do
    case start(opts) do
      {:ok, node} -> node
      {:error, error} -> raise error
    end
  end

  @doc """
  A fresh short node name: a prefix, this OS process's id and random bytes,
  unique across VMs and hosts.

      iex> RingTracer.Cluster.Distribution.unique_name("ringtracer") =~ ~r/^ringtracer_\\d+_[0-9a-f]{8}$/
      true
  """
  @spec unique_name(String.t()) :: String.t()
  def unique_name(prefix) do
    "#{prefix}_#{System.pid()}_#{Base.encode16(:crypto.strong_rand_bytes(4), case: :lower)}"
  end

  @doc """
  Parses a listen address (`"127.0.0.1"`, `"::1"`, `"0.0.0.0"`, `"10.0.0.5"`).

      iex> RingTracer.Cluster.Distribution.listen_address("10.0.0.5")
      {:ok, {10, 0, 0, 5}}
      iex> {:error, %RingTracer.Error{message: message}} = RingTracer.Cluster.Distribution.listen_address("10.0.0")
      iex> message
      "--listen must be an IP address such as 127.0.0.1 or 10.0.0.5, got: \\"10.0.0\\""
  """
  @spec listen_address(String.t() | :inet.ip_address() | nil) ::
          {:ok, :inet.ip_address()} | {:error, Error.t()}
  def listen_address(nil), do: {:ok, @loopback}
  def listen_address(ip) when is_tuple(ip), do: {:ok, ip}

  def listen_address(text) when is_binary(text) do
    case :inet.parse_strict_address(String.to_charlist(text)) do
      {:ok, ip} ->
        {:ok, ip}

      {:error, _} ->
        {:error,
         Error.new(
           :invalid_option,
           "--listen must be an IP address such as 127.0.0.1 or 10.0.0.5, got: #{inspect(text)}"
         )}
    end
  end

  @doc """
  Parses a port range, `"9100-9110"` (or `{9100, 9110}`).

      iex> RingTracer.Cluster.Distribution.ports("9100-9110")
      {:ok, {9100, 9110}}
      iex> {:error, %RingTracer.Error{message: message}} = RingTracer.Cluster.Distribution.ports("9110-9100")
      iex> message
      "--ports must be MIN-MAX with 1024 <= MIN <= MAX <= 65535, got: \\"9110-9100\\""
  """
  @spec ports(String.t() | {pos_integer(), pos_integer()} | nil) ::
          {:ok, {pos_integer(), pos_integer()} | nil} | {:error, Error.t()}
  def ports(nil), do: {:ok, nil}

  def ports({min, max} = range)
      when is_integer(min) and is_integer(max) and 1024 <= min and min <= max and max <= 65_535,
      do: {:ok, range}

  def ports(text) when is_binary(text) do
    with [a, b] <- String.split(text, "-"),
         {min, ""} <- Integer.parse(a),
         {max, ""} <- Integer.parse(b),
         {:ok, range} <- ports({min, max}) do
      {:ok, range}
    else
      _ -> bad_ports(text)
    end
  end

  def ports(other), do: bad_ports(other)

  defp bad_ports(value) do
    {:error,
     Error.new(
       :invalid_option,
       "--ports must be MIN-MAX with 1024 <= MIN <= MAX <= 65535, got: #{inspect(value)}"
     )}
  end

  @doc "Whether `ip` is a loopback address."
  @spec loopback?(:inet.ip_address()) :: boolean()
  def loopback?({127, _, _, _}), do: true
  def loopback?({0, 0, 0, 0, 0, 0, 0, 1}), do: true
  def loopback?(_), do: false

  @doc "Refuses a `:cookie` option: a cookie never goes on a command line."
  @spec refuse_cookie(keyword()) :: :ok | {:error, Error.t()}
  def refuse_cookie(opts) do
    if Keyword.has_key?(opts, :cookie) do
      {:error,
       Error.new(
         :cookie,
         "--cookie puts the secret on the command line, where every user of this machine can " <>
           "read it (/proc/PID/cmdline); put it in a file only you can read and give " <>
           "--cookie-file PATH (create one with: ringtracer cookie PATH)"
       )}
    else
      :ok
    end
  end

  @doc """
  Which transport `opts` and the VM's boot arguments give: `:tls` when the
  VM was booted with TLS distribution (and the folder is sound), `:plain`
  only with `insecure_plain: true`, else an error.
  """
  @spec transport(keyword()) :: {:ok, :tls | :plain} | {:error, Error.t()}
  def transport(opts) do
    cond do
      opts[:tls] && opts[:insecure_plain] ->
        {:error,
         Error.new(:invalid_option, "--tls and --insecure-plain exclude each other: choose one")}

      opts[:tls] ->
        with :ok <- TLS.check_booted(opts[:tls]), do: {:ok, :tls}

      TLS.enabled?() and opts[:insecure_plain] ->
        {:error,
         Error.new(
           :invalid_option,
           "--insecure-plain: this VM was booted with TLS distribution; start it " <>
             "through bin/ringtracer with --insecure-plain"
         )}

      TLS.enabled?() ->
        with :ok <- TLS.check_dir(TLS.booted_dir()), do: {:ok, :tls}

      opts[:insecure_plain] ->
        {:ok, :plain}

      true ->
        {:error,
         Error.new(
           :distribution,
           "distribution runs over TLS with mutual authentication, and this VM was " <>
             "booted without it: start it through bin/ringtracer (which makes your own " <>
             "certificates on first use), or give --tls DIR; --insecure-plain runs plain " <>
             "TCP instead, which any user of this machine who answers on port 4369 can " <>
             "read and alter"
         )}
    end
  end

  # A given cookie file is read (and checked) before anything starts. The
  # default one is left to Erlang, which reads it when the node starts (and
  # makes one, mode 0400, if there is none); it is checked here first for a
  # clearer message.
  defp cookie(nil) do
    path = Cookie.default_path()

    if File.exists?(path) do
      with {:ok, _} <- Cookie.read(path), do: {:ok, nil}
    else
      {:ok, nil}
    end
  end

  defp cookie(path), do: Cookie.read(Path.expand(path))

  defp set_cookie(nil), do: :ok
  defp set_cookie(cookie), do: Node.set_cookie(cookie)

  @doc """
  The node's full name and name type from `opts` (`:name`, `:sname`,
  `:generate`), checked before OTP sees it: OTP answers a bad name with
  pages of crash reports.

      iex> RingTracer.Cluster.Distribution.node_name([sname: "w1"], {127, 0, 0, 1})
      {:ok, "w1@localhost", :shortnames}
      iex> RingTracer.Cluster.Distribution.node_name([name: "w1@10.0.0.5"], {10, 0, 0, 5})
      {:ok, "w1@10.0.0.5", :longnames}
      iex> {:error, %RingTracer.Error{message: message}} =
      ...>   RingTracer.Cluster.Distribution.node_name([sname: "w 1"], {127, 0, 0, 1})
      iex> message
      "--sname: a node name is letters, digits, _ and - (at most 200), got: \\"w 1\\""
  """
  @spec node_name(keyword(), :inet.ip_address()) ::
          {:ok, String.t(), :shortnames | :longnames} | {:error, Error.t()}
  def node_name(opts, listen) do
    cond do
      opts[:name] -> long_name(opts[:name])
      opts[:sname] -> short_name(opts[:sname], listen)
      opts[:generate] -> {:ok, short(unique_name("ringtracer"), listen), :shortnames}
      true -> {:error, Error.new(:distribution, "give the node a name: --sname NAME")}
    end
  end

  @name_part ~r/^[A-Za-z0-9_-]{1,200}$/
  @short_host ~r/^[A-Za-z0-9-]{1,63}$/
  @long_host ~r/^[A-Za-z0-9-]{1,63}(\.[A-Za-z0-9-]{1,63})*$/

  defp short_name(name, listen) do
    case String.split(name, "@") do
      [n] ->
        with :ok <- name_part(n, "--sname"), do: {:ok, short(n, listen), :shortnames}

      [n, host] ->
        with :ok <- name_part(n, "--sname") do
          if Regex.match?(@short_host, host),
            do: {:ok, name, :shortnames},
            else:
              bad_name(
                "--sname #{inspect(name)}: a short name's host is one word without dots " <>
                  "(for NAME@HOST.DOMAIN give --name)"
              )
        end

      _ ->
        bad_name("--sname #{inspect(name)}: a node name holds at most one @")
    end
  end

  defp long_name(name) do
    case String.split(name, "@") do
      [n, host] ->
        with :ok <- name_part(n, "--name") do
          if Regex.match?(@long_host, host) or
               match?({:ok, _}, :inet.parse_strict_address(String.to_charlist(host))),
             do: {:ok, name, :longnames},
             else:
               bad_name(
                 "--name #{inspect(name)}: the host must be a host name (w1.example.org) " <>
                   "or an IP address"
               )
        end

      _ ->
        bad_name("--name takes NAME@HOST (for example w1@10.0.0.5), got: #{inspect(name)}")
    end
  end

  defp name_part(n, flag) do
    if Regex.match?(@name_part, n),
      do: :ok,
      else:
        bad_name(
          "#{flag}: a node name is letters, digits, _ and - (at most 200), got: #{inspect(n)}"
        )
  end

  defp bad_name(message), do: {:error, Error.new(:invalid_option, message)}

  # On loopback a short name lives on `localhost`: the host name of the
  # machine may resolve to an address the node does not listen on.
  defp short(name, listen) do
    if String.contains?(name, "@") or not loopback?(listen),
      do: name,
      else: name <> "@localhost"
  end

  defp configure_listener(listen, ports) do
    :ok = Application.put_env(:kernel, :inet_dist_use_interface, listen)

    case ports do
      nil ->
        :ok

      {min, max} ->
        :ok = Application.put_env(:kernel, :inet_dist_listen_min, min)
        :ok = Application.put_env(:kernel, :inet_dist_listen_max, max)
    end
  end

  # epmd, the port-mapper other nodes ask for our port, must run before the
  # node starts. One started here listens on loopback (and on the listen
  # address, if another is given). One that already runs is kept; a check
  # says whether it is reachable where it must be, whose it is, and warns
  # when it is reachable where it need not be.
  defp ensure_epmd(listen, transport, opts) do
    unless epmd_at?(@loopback), do: start_epmd(listen)

    if wait_epmd(@loopback, 40) do
      listeners = Epmd.listeners()

      with :ok <- reachable(listen, listeners),
           :ok <- owner(listeners, transport, opts) do
        # /proc said where epmd listens: the probe of each own address is
        # needed only when it could not, or when that is beyond loopback
        if loopback?(listen) and not loopback_only?(listeners), do: warn_exposed_epmd()
        :ok
      end
    else
      {:error,
       Error.new(:distribution, "epmd (the Erlang port mapper) did not start on 127.0.0.1:4369")}
    end
  end

  defp reachable(listen, listeners) do
    cond do
      loopback?(listen) ->
        :ok

      any_address?(listen) ->
        if listeners != [] and loopback_only?(listeners),
          do: epmd_elsewhere("every address (--listen #{:inet.ntoa(listen)})"),
          else: :ok

      epmd_at?(listen) ->
        :ok

      true ->
        epmd_elsewhere(to_string(:inet.ntoa(listen)))
    end
  end

  defp epmd_elsewhere(where) do
    {:error,
     Error.new(
       :distribution,
       "epmd runs but does not listen on #{where}, only on loopback, so other machines " <>
         "cannot find this node; stop it (epmd -kill) and start again"
     )}
  end

  # An epmd of another user answers every port query: with plain
  # distribution she can hand out a relay of hers and read and alter the
  # stream; TLS refuses her relay, but she can still misdirect.
  defp owner(:unknown, _transport, _opts), do: :ok

  defp owner(listeners, transport, opts) do
    case Epmd.foreign(listeners, Epmd.own_uid()) do
      [] ->
        :ok

      foreign ->
        whose = "epmd (port 4369) belongs to #{Epmd.describe(foreign)}, not to you"

        cond do
          transport == :tls ->
            warn(
              "#{whose}: that user learns this node's name and port and can misdirect " <>
                "connections between nodes (TLS refuses her, so she can stop nodes from " <>
                "finding each other, but not read or join the cluster); have it stopped " <>
                "and start a node first"
            )

          opts[:allow_foreign_epmd] ->
            warn(
              "#{whose}, and distribution is plain TCP (--insecure-plain, " <>
                "--allow-foreign-epmd): that user can read and alter everything this node says"
            )

          true ->
            {:error,
             Error.new(
               :distribution,
               "#{whose}: with plain TCP distribution (--insecure-plain) that user could " <>
                 "read and alter everything this node says, and so run code on it. Drop " <>
                 "--insecure-plain (distribution over TLS is the default), or give " <>
                 "--allow-foreign-epmd to go on anyway"
             )}
        end
    end
  end

  defp warn(message) do
    IO.puts(Console.err(), "ringtracer: warning: #{message}")
    :ok
  end

  defp start_epmd(listen) do
    env =
      cond do
        # asked for (--listen 0.0.0.0): every address, whatever the caller's environment says
        any_address?(listen) -> [{"ERL_EPMD_ADDRESS", nil}]
        loopback?(listen) -> [{"ERL_EPMD_ADDRESS", "127.0.0.1"}]
        true -> [{"ERL_EPMD_ADDRESS", "127.0.0.1,#{:inet.ntoa(listen)}"}]
      end

    case System.find_executable("epmd") do
      nil -> :ok
      epmd -> System.cmd(epmd, ["-daemon"], env: env, stderr_to_stdout: true)
    end
  end

  defp any_address?({0, 0, 0, 0}), do: true
  defp any_address?({0, 0, 0, 0, 0, 0, 0, 0}), do: true
  defp any_address?(_), do: false

  defp wait_epmd(_ip, 0), do: false

  defp wait_epmd(ip, tries) do
    epmd_at?(ip) or
      (
        Process.sleep(50)
        wait_epmd(ip, tries - 1)
      )
  end

  defp epmd_at?(ip, timeout \\ 500) do
    case :gen_tcp.connect(ip, Epmd.port(), [:binary, active: false], timeout) do
      {:ok, socket} ->
        :gen_tcp.close(socket)
        true

      {:error, _} ->
        false
    end
  end

  # Whether /proc showed every epmd listener on a loopback address.
  defp loopback_only?(:unknown), do: false
  defp loopback_only?(listeners), do: Enum.all?(listeners, &loopback?(&1.address))

  defp warn_exposed_epmd do
    exposed = Enum.filter(own_addresses(), &epmd_at?(&1, 200))

    if exposed != [] do
      warn(
        "epmd (port 4369) was started before, by someone else, and listens on " <>
          "#{Enum.map_join(exposed, ", ", &:inet.ntoa/1)} too: it tells anyone there which " <>
          "nodes run here. Restart it on loopback: epmd -kill, then " <>
          "ERL_EPMD_ADDRESS=127.0.0.1 epmd -daemon"
      )
    end
  end

  # This machine's non-loopback IPv4 addresses.
  defp own_addresses do
    case :inet.getifaddrs() do
      {:ok, ifs} ->
        for {_, props} <- ifs,
            {:addr, {_, _, _, _} = ip} <- props,
            not loopback?(ip),
            do: ip

      _ ->
        []
    end
  end

  defp free_name(name) do
    [short | _] = String.split(name, "@")

    case :erl_epmd.names() do
      {:ok, names} ->
        if Enum.any?(names, fn {n, _port} -> List.to_string(n) == short end),
          do:
            {:error,
             Error.new(
               :distribution,
               "the node name #{short} is in use on this machine (is a worker already " <>
                 "running as #{name}?); choose another with --sname"
             )},
          else: :ok

      _ ->
        :ok
    end
  end

  defp start_node(name, type) do
    case quietly(fn -> Node.start(String.to_atom(name), type) end) do
      {:ok, _} ->
        :ok

      {:error, reason} ->
        {:error,
         Error.new(
           :distribution,
           "could not start node #{name}: #{explain(reason)}"
         )}
    end
  end

  # OTP reports a distribution that fails to start with pages of
  # supervisor reports and a notice; the error returned says it in one line.
  # While any start runs, a primary filter drops OTP's own reports (the
  # `[:otp, :sasl]` domain and legacy `error_logger` messages) and nothing
  # else: the logger's level is the VM's, and lowering it here lost other
  # processes' logs meanwhile (and, with two starts at once, could stay
  # lowered).
  defp quietly(fun) do
    starting = starting()
    :atomics.add(starting, 1, 1)
    _ = :logger.add_primary_filter(__MODULE__, {&__MODULE__.drop_start_reports/2, starting})

    try do
      fun.()
    after
      :atomics.sub(starting, 1, 1)
    end
  end

  defp starting, do: :persistent_term.get({__MODULE__, :starting})

  # The count of starts under way, made once as the module loads (the code
  # server loads a module once, so no two callers make two).
  @on_load :make_starting
  defp make_starting do
    :persistent_term.put({__MODULE__, :starting}, :atomics.new(1, []))
  end

  @doc false
  # The primary filter of `quietly/1`: while a start runs, OTP's reports go.
  @spec drop_start_reports(:logger.log_event(), :atomics.atomics_ref()) :: :logger.filter_return()
  def drop_start_reports(%{meta: meta}, starting) do
    cond do
      :atomics.get(starting, 1) == 0 -> :ignore
      Map.get(meta, :domain) == [:otp, :sasl] -> :stop
      Map.has_key?(meta, :error_logger) -> :stop
      true -> :ignore
    end
  end

  defp explain({{:shutdown, {:failed_to_start_child, :net_kernel, {:EXIT, :nodistribution}}}, _}),
    do: "the name is in use, or epmd cannot be reached"

  defp explain({{:shutdown, {:failed_to_start_child, :net_kernel, reason}}, _}),
    do: inspect(reason)

  defp explain(reason), do: inspect(reason)
end
