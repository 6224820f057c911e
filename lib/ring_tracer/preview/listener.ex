defmodule RingTracer.Preview.Listener do
  @moduledoc false
  # The guarded `:httpd` both the live preview (`RingTracer.Preview`) and the
  # farm's dashboard (`RingTracer.Farm.Dashboard`) serve with: OTP's `:httpd`
  # started stand-alone with one module of the caller's (no directory
  # listing, no file serving by path, no CGI), no `Server` header, one
  # deadline of #{5} s for a request's line and headers, and a random token
  # as the first segment of every path.
  #
  # `check/3` is what every request goes through first: a target that is not
  # a path is 400, a `Host` not the server's own address 421, a path outside
  # the token 404, a method other than GET 405; a connection whose request
  # passed them is admitted (it holds the token). `sweep/4` keeps the
  # connections that are neither long-lived streams nor admitted to a few,
  # oldest dropped first. `close/1` stops a server so that its port accepts
  # nothing more.

  require Record

  Record.defrecordp(:mod, Record.extract(:mod, from_lib: "inets/include/httpd.hrl"))

  @enforce_keys [:httpd, :port, :addr, :listener, :connections, :admitted]
  defstruct [:httpd, :port, :addr, :listener, :connections, :admitted]

  @type t :: %__MODULE__{
          httpd: pid(),
          port: :inet.port_number(),
          addr: :inet.ip_address(),
          listener: port() | nil,
          connections: term(),
          admitted: :ets.tid()
        }

  # Seconds a connection has to send its request line and headers; the
  # application's `:request_deadline_s` sets it where a test needs less.
  @request_deadline_s 5
  # How long a connection is kept, whatever the others, to show the token.
  @grace_ms 1_000

  @doc "A new random token: 128 bits, URL-safe base64."
  @spec token() :: String.t()
  def token, do: Base.url_encode64(:crypto.strong_rand_bytes(16), padding: false)

  @doc """
  Starts a stand-alone `:httpd` whose only module is `module`; its handler
  finds `data` with `data/1`. The caller owns the table of admitted
  connections: call it from the process that sweeps.

  ## Options

    * `:listen` — the address (default `{127, 0, 0, 1}`)
    * `:port` — default 0, a free one
    * `:root` — the server's root folder (httpd needs one; nothing is
      served from it by path)
    * `:name` — the server's name (a charlist)
    * `:max_clients` — httpd's own limit on connections (a backstop)
  """
  @spec start(module(), term(), keyword()) :: {:ok, t()} | {:error, {:listen, term()}}
  def start(module, data, opts) do
    addr = Keyword.get(opts, :listen, {127, 0, 0, 1})
    root = String.to_charlist(Keyword.fetch!(opts, :root))
    # The request processes whose request passed `check/3`: they write
    # themselves in, the sweep leaves them alone.
    admitted = :ets.new(__MODULE__, [:set, :public, write_concurrency: true])

    config = [
      port: Keyword.get(opts, :port, 0),
      server_name: Keyword.fetch!(opts, :name),
      server_root: root,
      document_root: root,
      bind_address: addr,
      ipfamily: if(tuple_size(addr) == 8, do: :inet6, else: :inet),
      modules: [module],
      max_clients: Keyword.fetch!(opts, :max_clients),
      # No Server header: nothing to tell a prober what answers here.
      server_tokens: :none,
      # One deadline, from the connection (or the end of the previous
      # response) to the end of the request's headers: httpd arms one timer
      # and cancels it only when the request is whole, so a client that
      # trickles its request a byte at a time is cut off at the deadline.
      # It is also how long a kept-alive connection may idle.
      keep_alive_timeout:
        Application.get_env(:ring_tracer, :request_deadline_s, @request_deadline_s),
      # A token is never in httpd's configuration, which httpd prints when
      # it cannot start: it is in a table of the caller's, in `data`.
      ring_tracer_listener: data,
      ring_tracer_admitted: admitted
    ]

    with {:ok, httpd} <- :inets.start(:httpd, config, :stand_alone),
         {:ok, port} <- port(httpd, config) do
      {:ok,
       %__MODULE__{
         httpd: httpd,
         port: port,
         addr: addr,
         listener: listener(addr, port),
         connections: :httpd_connection_sup.connection_sup(addr, port),
         admitted: admitted
       }}
    else
      {:error, reason} ->
        :ets.delete(admitted)
        {:error, {:listen, listen_error(reason)}}
    end
  end

  @doc "The `data` given to `start/3`, in the handler of a request."
  @spec data(tuple()) :: term()
  def data(m), do: :httpd_util.lookup(mod(m, :config_db), :ring_tracer_listener)

  # What stopped httpd from listening (`:eaddrinuse`, `:eacces`...), out of
  # its supervisors' reports; a port this VM already serves is in use too.
  defp listen_error({:listen, reason}), do: reason

  defp listen_error({:shutdown, {:failed_to_start_child, _, {:already_started, _}}}),
    do: :eaddrinuse

  defp listen_error({:shutdown, {:failed_to_start_child, _, inner}}), do: listen_error(inner)
  defp listen_error(other), do: other

  # httpd.info/2 knows only servers started under the :inets application;
  # this one is ours (stand-alone, linked), and its instance supervisor is
  # named by address and port.
  defp port(httpd, config) do
    case for {{:httpd_instance_sup, _addr, port, _}, _, _, _} <- Supervisor.which_children(httpd),
             do: port do
      [port] ->
        {:ok, port}

      # Started without a listener (with port 0, httpd does not report why:
      # a listen of our own, closed at once, tells).
      [] ->
        :inets.stop(:stand_alone, httpd)

        case :gen_tcp.listen(config[:port], ip: config[:bind_address]) do
          {:ok, socket} ->
            :gen_tcp.close(socket)
            {:error, :not_listening}

          {:error, reason} ->
            {:error, {:listen, reason}}
        end
    end
  end

  # The httpd's listening socket: the one of this VM's TCP sockets bound to
  # its address and port that listens (a connection accepted meanwhile has
  # the same local address).
  defp listener(addr, port),
    do: Enum.find(:erlang.ports(), &listening?(&1, addr, port))

  defp listening?(p, addr, port) do
    match?({:name, ~c"tcp_inet" ++ _}, :erlang.port_info(p, :name)) and
      :inet.sockname(p) == {:ok, {addr, port}} and
      :listen in Map.get(:inet.info(p), :states, [])
  catch
    _, _ -> false
  end

  @doc """
  Stops the server: when it returns, its listening socket is closed.

  A stand-alone httpd is stopped by an exit signal, which returns at once,
  and its listening socket belongs to a process of its own outside its
  supervision tree, which closes it when it learns (by a link) that the
  acceptor is gone: the httpd's DOWN can come before that. So this waits
  for the httpd, then closes the socket if it is still open (nothing uses
  it any more) and waits for that, each for at most 5 s.
  """
  @spec close(t()) :: :ok
  def close(%__MODULE__{httpd: httpd, listener: listener}) do
    ref = Process.monitor(httpd)
    :inets.stop(:stand_alone, httpd)
    await_down(ref, 5_000)

    if listener do
      ref = :erlang.monitor(:port, listener)
      if :erlang.port_info(listener) != :undefined, do: :erlang.port_close(listener)
      await_down(ref, 5_000)
    end

    :ok
  catch
    :error, :badarg -> :ok
  end

  defp await_down(ref, ms) do
    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    after
      ms -> :ok
    end
  end

  @doc """
  The connections that are neither `streams` nor admitted (a request on
  its way without the token, a kept-alive connection that never showed
  it), each with when a sweep first saw it (`seen`, from the previous
  sweep): beyond `max`, the oldest are killed, but never one this sweep
  sees for the first time, nor one first seen less than `grace_ms` ago
  (default #{@grace_ms}: time for a request to show the token on a loaded
  machine, where one sweep's interval was once too little). A connection
  is admitted as soon as its request
  passes `check/3`, however long its answer then takes (a stream joining
  a server that runs late on a loaded machine), so clients that hold
  connections open without the token (or many of them, reconnecting as
  fast as they are dropped) cannot keep the owner from the page. Returns
  the new `seen`.
  """
  @spec sweep(
          t(),
          %{pid() => integer()},
          %{optional(pid()) => term()},
          non_neg_integer(),
          non_neg_integer()
        ) :: %{pid() => integer()}
  def sweep(
        %__MODULE__{connections: sup, admitted: admitted},
        seen,
        streams,
        max,
        grace_ms \\ @grace_ms
      ) do
    now = System.monotonic_time(:millisecond)
    live = connections(sup)
    admitted = forget_gone(admitted, live)

    waiting =
      for pid <- live,
          not is_map_key(streams, pid),
          not MapSet.member?(admitted, pid),
          into: %{},
          do: {pid, Map.get(seen, pid, now)}

    excess = map_size(waiting) - max

    if excess > 0 do
      # Never one this sweep sees for the first time: a request that has
      # just connected has until the next sweep to show the token, however
      # many others keep reconnecting as fast as they are dropped.
      dropped =
        waiting
        |> Enum.filter(fn {pid, at} -> is_map_key(seen, pid) and now - at >= grace_ms end)
        |> Enum.sort_by(&elem(&1, 1))
        |> Enum.take(excess)
        |> Enum.map(&elem(&1, 0))

      Enum.each(dropped, &Process.exit(&1, :kill))
      Map.drop(waiting, dropped)
    else
      waiting
    end
  end

  # The admitted connections still open (the table forgets the others).
  defp forget_gone(table, live) do
    live = MapSet.new(live)

    {keep, gone} =
      table
      |> :ets.tab2list()
      |> Enum.map(&elem(&1, 0))
      |> Enum.split_with(&MapSet.member?(live, &1))

    Enum.each(gone, &:ets.delete(table, &1))
    MapSet.new(keep)
  end

  defp connections(sup) do
    for {_, pid, _, _} <- Supervisor.which_children(sup), is_pid(pid), do: pid
  catch
    :exit, _ -> []
  end

  @doc """
  The names a request's `Host` may give for a server listening on `addr`:
  the loopback names on loopback, that address's own elsewhere, and any
  name on a wildcard address (reached by whatever name the network gives
  the machine).

      iex> RingTracer.Preview.Listener.hosts({127, 0, 0, 1})
      ["127.0.0.1", "localhost", "[::1]"]
      iex> RingTracer.Preview.Listener.hosts({0, 0, 0, 0})
      :any
  """
  @spec hosts(:inet.ip_address()) :: [String.t()] | :any
  def hosts(addr) do
    case addr do
      {0, 0, 0, 0} -> :any
      {0, 0, 0, 0, 0, 0, 0, 0} -> :any
      {127, _, _, _} -> [to_string(:inet.ntoa(addr)), "localhost", "[::1]"]
      {0, 0, 0, 0, 0, 0, 0, 1} -> ["[::1]", "localhost", "127.0.0.1"]
      {_, _, _, _} -> [to_string(:inet.ntoa(addr))]
      _ -> ["[#{:inet.ntoa(addr)}]"]
    end
  end

  @doc """
  A server's secret: a table, readable by its request handlers, of its
  token and the host names a request may give (`hosts/1` of `addr`).
  """
  @spec secret(String.t(), :inet.ip_address()) :: :ets.tid()
  def secret(token, addr) do
    table = :ets.new(__MODULE__, [:set, :protected, read_concurrency: true])
    :ets.insert(table, {:address, token, hosts(addr)})
    table
  end

  @doc "The token and host names in `secret/2`'s table (none once the server is stopping)."
  @spec address(:ets.tid()) :: {String.t() | nil, [String.t()] | :any}
  def address(secret) do
    [{:address, token, hosts}] = :ets.lookup(secret, :address)
    {token, hosts}
  rescue
    ArgumentError -> {nil, []}
  end

  @doc "An address as a URL's host: `127.0.0.1`, `[::1]`."
  @spec host(:inet.ip_address()) :: String.t()
  def host(addr) when tuple_size(addr) == 8, do: "[#{:inet.ntoa(addr)}]"
  def host(addr), do: to_string(:inet.ntoa(addr))

  @doc """
  The first checks of every request, in order: `{:ok, path}` (the path
  under the token, from `/`, without its query) or `{:error, response}`,
  the handler's answer: 400 for a target that is not a path (the absolute
  form `GET http://host/...` that proxies take, or `*`), 421 for a `Host`
  not in `hosts`, 404 outside the token (`token` nil: the server is
  stopping), 405 for a method other than GET. A request that passes them
  admits its connection (`sweep/4`).
  """
  @spec check(tuple(), String.t() | nil, [String.t()] | :any) ::
          {:ok, String.t()} | {:error, {:proceed, list()}}
  def check(m, token, hosts) do
    full = m |> mod(:request_uri) |> to_string() |> String.split("?", parts: 2) |> hd()

    path =
      case String.split(full, "/", parts: 3) do
        ["", ^token, rest] when token != nil -> "/" <> rest
        _ -> nil
      end

    cond do
      # Only the origin form (`GET /path`): the absolute form is for
      # proxies, and this server is none.
      not origin_form?(m) -> status(400, "only a path as the request target")
      not host_allowed?(m, hosts) -> status(421, "the server answers on its own address only")
      path == nil -> status(404, "not found")
      mod(m, :method) != ~c"GET" -> status(405, "only GET")
      true -> admit(m, path)
    end
  end

  # This connection holds the token: the sweep leaves it alone from now on
  # (the table is gone once the server stops).
  defp admit(m, path) do
    :ets.insert(:httpd_util.lookup(mod(m, :config_db), :ring_tracer_admitted), {self()})
    {:ok, path}
  rescue
    ArgumentError -> {:ok, path}
  end

  @doc "A response of `code` with a short text, as a handler returns it."
  @spec status(pos_integer(), String.t()) :: {:error, {:proceed, list()}}
  def status(code, text),
    do: {:error, {:proceed, [{:response, {code, String.to_charlist(text)}}]}}

  @doc """
  A 200 response of `body` with content type `type` (a charlist), not
  cached, not sniffed, under `csp` (the Content-Security-Policy).
  """
  @spec body(iodata(), charlist(), charlist()) :: {:proceed, list()}
  def body(body, type, csp) do
    body = IO.iodata_to_binary(body)

    head = [
      code: 200,
      content_type: type,
      content_length: Integer.to_charlist(byte_size(body)),
      cache_control: ~c"no-store",
      "x-content-type-options": ~c"nosniff",
      "content-security-policy": csp
    ]

    {:proceed, [{:response, {:response, head, body}}]}
  end

  defp origin_form?(m) do
    match?(
      [_method, "/" <> _, _version],
      m |> mod(:request_line) |> to_string() |> String.split(" ")
    )
  end

  defp host_allowed?(_m, :any), do: true

  defp host_allowed?(m, hosts) do
    case List.keyfind(mod(m, :parsed_header), ~c"host", 0) do
      {_, value} ->
        host = value |> to_string() |> String.downcase()
        # the name without its port ("[::1]:8080" -> "[::1]")
        name = String.replace(host, ~r/:\d+\z/, "")
        name in hosts

      nil ->
        false
    end
  end

  @doc """
  Why a server could not listen, in words (`what`: "port 8080 on
  127.0.0.1 is in use ...").
  """
  @spec failure(term(), :inet.ip_address(), :inet.port_number()) :: String.t()
  def failure(reason, addr, port) do
    addr = host(addr)

    case reason do
      :eaddrinuse ->
        "port #{port} on #{addr} is in use (another program listens there): " <>
          "give another port, or 0 for a free one"

      :eacces ->
        "may not listen on port #{port} on #{addr} (ports below 1024 need privileges): " <>
          "give another port, or 0 for a free one"

      :eaddrnotavail ->
        "cannot listen on #{addr}: it is not an address of this machine"

      :not_listening ->
        "could not listen on #{addr}, port #{port} (is #{addr} an address of this machine?)"

      other ->
        "could not listen on #{addr}, port #{port}: #{:inet.format_error(other)}"
    end
  end
end
