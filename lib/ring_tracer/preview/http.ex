defmodule RingTracer.Preview.HTTP do
  @moduledoc false
  # The only module of a preview's `:httpd` server (so no directory listing,
  # no file serving by path, no CGI): it answers `GET` for the page's three
  # files, by fixed name from `priv/preview`, and `GET /events`, the job's
  # Server-Sent Events stream, all under `/TOKEN/`, the preview's random
  # first segment. Anything else is 404 (an unknown path, or one outside the
  # token) or 405 (a method other than GET); a request target that is not a
  # path (the absolute form `GET http://host/...`, or `*`) is 400; a request
  # whose `Host` header names another host than the preview's address
  # (`hosts/1`: a page that rebound its own name to 127.0.0.1) is 421. No
  # response has a `Server` header.
  #
  # `/events` streams the log of `RingTracer.Preview.Server` from its first
  # frame (or after `Last-Event-ID`, when a browser reconnects), in chunks of
  # up to 256 KB, at most one every #{40} ms, until the job's end frame. The
  # handler reads the log itself: a slow viewer lags without holding any
  # buffer. Every send has a deadline (2 s): a viewer whose connection
  # takes nothing for that long while a chunk waits (so at most one chunk
  # waits in the VM for it) is disconnected; a browser reconnects from its
  # `Last-Event-ID`. Beyond `:max_viewers` streams at once, `/events` is 503.

  require Record

  alias RingTracer.Preview.Listener

  Record.defrecordp(:mod, Record.extract(:mod, from_lib: "inets/include/httpd.hrl"))

  @files %{
    "/" => {"index.html", ~c"text/html; charset=utf-8"},
    "/index.html" => {"index.html", ~c"text/html; charset=utf-8"},
    "/preview.js" => {"preview.js", ~c"text/javascript; charset=utf-8"},
    "/preview.css" => {"preview.css", ~c"text/css; charset=utf-8"}
  }
  @chunk_bytes 256 * 1024
  @interval_ms 40
  @keep_alive_ms 10_000
  @send_timeout_ms 2_000
  @join_timeout_ms 5_000
  @csp ~c"default-src 'self'; img-src 'self' data:; connect-src 'self'; frame-ancestors 'none'"

  @doc "The folder of the page's files."
  @spec root() :: String.t()
  def root, do: Application.app_dir(:ring_tracer, "priv/preview")

  @doc """
  The names a request's `Host` may give for a preview listening on `addr`:
  the loopback names on loopback, that address's own elsewhere, and any
  name on a wildcard address (`--listen 0.0.0.0`: reached by whatever name
  the network gives the machine).

      iex> RingTracer.Preview.HTTP.hosts({127, 0, 0, 1})
      ["127.0.0.1", "localhost", "[::1]"]
      iex> RingTracer.Preview.HTTP.hosts({10, 0, 0, 5})
      ["10.0.0.5"]
      iex> RingTracer.Preview.HTTP.hosts({0, 0, 0, 0})
      :any
  """
  @spec hosts(:inet.ip_address()) :: [String.t()] | :any
  defdelegate hosts(addr), to: Listener

  @doc false
  def unquote(:do)(m) do
    {server, table, secret} = Listener.data(m)
    {token, hosts} = Listener.address(secret)

    case Listener.check(m, token, hosts) do
      {:error, response} ->
        response

      {:ok, "/events"} ->
        stream(m, server, table)

      {:ok, path} when is_map_key(@files, path) ->
        {name, type} = Map.fetch!(@files, path)
        Listener.body(File.read!(Path.join(root(), name)), type, @csp)

      {:ok, _} ->
        {:error, response} = Listener.status(404, "not found")
        response
    end
  end

  defp stream(m, server, table) do
    Process.flag(:priority, :low)
    socket = mod(m, :socket)
    # Every send to the viewer has a deadline: one whose connection takes
    # nothing for @send_timeout_ms while a chunk waits is disconnected, and
    # at most one chunk waits in the VM for it.
    _ = :inet.setopts(socket, send_timeout: @send_timeout_ms, send_timeout_close: true)

    case join(server, socket) do
      :ok ->
        ref = Process.monitor(server)

        headers =
          [content_type: ~c"text/event-stream", cache_control: ~c"no-store"] ++
            if mod(m, :http_version) == ~c"HTTP/1.1",
              do: [transfer_encoding: ~c"chunked"],
              else: []

        :httpd_response.send_header(m, 200, headers)

        if loop(m, server, table, ref, last_event_id(m)) == :ok,
          do: :httpd_response.send_final_chunk(m, false)

        send(server, {:viewer_done, self()})
        Process.demonitor(ref, [:flush])
        {:proceed, [{:response, {:already_sent, 200, 0}}]}

      {:error, :full} ->
        {:proceed, [{:response, {503, ~c"as many viewers as the preview takes"}}]}
    end
  end

  defp join(server, socket) do
    GenServer.call(server, {:viewer, self(), socket}, @join_timeout_ms)
  catch
    :exit, _ -> {:error, :full}
  end

  defp last_event_id(m) do
    with {_, v} <- List.keyfind(mod(m, :parsed_header), ~c"last-event-id", 0),
         {n, ""} <- Integer.parse(to_string(v)) do
      n
    else
      _ -> 0
    end
  end

  defp loop(m, server, table, ref, cursor) do
    case read(table, cursor, [], 0) do
      :gone ->
        :closed

      {[], _, _} ->
        send(server, {:wait, self(), cursor})

        receive do
          :preview_more ->
            loop(m, server, table, ref, cursor)

          {:DOWN, ^ref, _, _, _} ->
            :ok
        after
          @keep_alive_ms ->
            with :ok <- deliver(m, ": keep-alive\n\n"), do: loop(m, server, table, ref, cursor)
        end

      {chunk, last, ended?} ->
        with :ok <- deliver(m, chunk) do
          if ended? do
            :ok
          else
            Process.sleep(@interval_ms)
            loop(m, server, table, ref, last)
          end
        end
    end
  end

  # Frames after `cursor`, up to about @chunk_bytes: `{iodata, last, ended?}`.
  defp read(table, cursor, acc, bytes) do
    case :ets.next(table, cursor) do
      :"$end_of_table" ->
        {Enum.reverse(acc), cursor, false}

      seq ->
        case :ets.lookup(table, seq) do
          [{^seq, frame, last?}] ->
            acc = [["id: ", Integer.to_string(seq), "\n", frame] | acc]
            bytes = bytes + byte_size(frame)

            if last? or bytes >= @chunk_bytes,
              do: {Enum.reverse(acc), seq, last?},
              else: read(table, seq, acc, bytes)

          # Forgotten meanwhile (a sequence's image complete): read on.
          [] ->
            read(table, seq, acc, bytes)
        end
    end
  rescue
    ArgumentError -> :gone
  end

  # As iodata (a list): the chunk's frames go to the socket as they are in
  # the log, not copied into one binary first.
  defp deliver(m, data) do
    case :httpd_response.send_chunk(m, List.wrap(data), false) do
      :ok -> :ok
      _ -> :closed
    end
  catch
    _, _ -> :closed
  end
end
