defmodule RingTracer.Preview.HTTPTest do
  use ExUnit.Case, async: false
  # `bin/ringtracer test` runs it in a second test VM (docs/testing.md).
  @moduletag :second_vm
  doctest RingTracer.Preview
  doctest RingTracer.Preview.HTTP

  import ExUnit.CaptureIO

  alias RingTracer.Bench.Preview, as: Viewer
  alias RingTracer.Preview

  @scene "priv/scenes/tetra_s1.nff"

  # `@tag request_deadline_s: n`: the preview's request deadline is n s, not 5.
  setup ctx do
    if ctx[:request_deadline_s] do
      Application.put_env(:ring_tracer, :request_deadline_s, ctx.request_deadline_s)
    end

    {:ok, preview} = Preview.start()
    Application.delete_env(:ring_tracer, :request_deadline_s)
    on_exit(fn -> Preview.stop(preview, 0) end)
    {:ok, preview: preview}
  end

  # A connection per request: httpc keeps one open between requests, and
  # sending on it as the server closes it (idle past the request deadline,
  # 2 s in some tests) fails with :socket_closed_remotely, as it did once.
  defp get(url, method \\ :get) do
    {:ok, {{_, code, _}, headers, body}} =
      :httpc.request(
        method,
        {String.to_charlist(url), [{~c"connection", ~c"close"}]},
        [autoredirect: false],
        []
      )

    {code, Map.new(headers, fn {k, v} -> {to_string(k), to_string(v)} end), to_string(body)}
  end

  # Every frame of a finished job's stream, as {id, event, data}.
  defp frames(url, headers \\ []) do
    {:ok, {{_, 200, _}, _, body}} =
      :httpc.request(:get, {String.to_charlist(url <> "events"), headers}, [timeout: 20_000], [])

    body
    |> to_string()
    |> String.split("\n\n", trim: true)
    |> Enum.map(fn frame ->
      [_, id, name, data] = Regex.run(~r/\Aid: (\d+)\nevent: (\w+)\ndata: (.*)\z/s, frame)
      {String.to_integer(id), name, :jiffy.decode(data, [:return_maps, :use_nil])}
    end)
  end

  # This VM's listening sockets on `port`.
  defp listeners(port) do
    for p <- :erlang.ports(),
        match?({:name, ~c"tcp_inet" ++ _}, :erlang.port_info(p, :name)),
        match?({:ok, {_, ^port}}, :inet.sockname(p)),
        :listen in Map.get(:inet.info(p), :states, []),
        do: {p, :erlang.port_info(p, :connected)}
  end

  # Whether an HTTP GET of `url` gets a preview's page.
  defp serves_page?(url) do
    case :httpc.request(
           :get,
           {String.to_charlist(url), []},
           [timeout: 2_000, connect_timeout: 1_000, autoredirect: false],
           []
         ) do
      {:ok, {{_, 200, _}, _, body}} -> to_string(body) =~ ~s(<script src="preview.js">)
      _ -> false
    end
  end

  test "serves the page's files and nothing else, on loopback", %{preview: p} do
    assert p.url =~ ~r|\Ahttp://127\.0\.0\.1:\d+/[\w-]{22}/\z|

    assert {200, h, body} = get(p.url)
    assert h["content-type"] =~ "text/html"
    assert body =~ ~s(<script src="preview.js">)
    assert h["content-security-policy"] =~ "default-src 'self'"
    assert {200, %{"content-type" => "text/javascript" <> _}, _} = get(p.url <> "preview.js")
    assert {200, %{"content-type" => "text/css" <> _}, _} = get(p.url <> "preview.css")

    for path <- ["index.htm", "../mix.exs", "%2e%2e/mix.exs", "priv/preview/", "preview", "x.js"],
        do: assert({404, _, _} = get(p.url <> path), path)

    assert {405, _, _} = get(p.url, :delete)
    assert {405, _, _} = get(p.url <> "events", :head)

    # Outside its random first segment there is nothing, whatever the method.
    root = "http://127.0.0.1:#{p.port}/"
    other = String.replace(p.url, ~r|/[\w-]{22}/\z|, "/#{String.duplicate("A", 22)}/")

    for url <- [root, root <> "events", root <> "preview.js", other, other <> "events"],
        method <- [:get, :delete],
        do: assert({404, _, _} = get(url, method), "#{method} #{url}")

    # A page that rebinds a name of its own to 127.0.0.1 is not answered.
    for host <- ["evil.example", "evil.example:#{p.port}", "127.0.0.1.evil.example"] do
      {:ok, {{_, code, _}, _, _}} =
        :httpc.request(:get, {String.to_charlist(p.url), [{~c"host", ~c"#{host}"}]}, [], [])

      assert code == 421, host
    end

    for host <- ["localhost:#{p.port}", "LOCALHOST", "127.0.0.1"] do
      {:ok, {{_, code, _}, _, _}} =
        :httpc.request(:get, {String.to_charlist(p.url), [{~c"host", ~c"#{host}"}]}, [], [])

      assert code == 200, host
    end

    # Nothing answers on this machine's other addresses.
    {:ok, ifs} = :inet.getifaddrs()

    for {_, opts} <- ifs,
        addr <- Keyword.get_values(opts, :addr),
        tuple_size(addr) == 4 and addr != {127, 0, 0, 1} do
      assert {:error, _} = :gen_tcp.connect(addr, p.port, [], 1_000)
    end
  end

  # One raw HTTP/1.1 exchange on `port`: the response's status line and headers.
  defp raw(port, request) do
    {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false])
    :ok = :gen_tcp.send(sock, request)
    {:ok, head} = :gen_tcp.recv(sock, 0, 5_000)
    :gen_tcp.close(sock)
    head |> String.split("\r\n\r\n") |> hd()
  end

  test "a request target in absolute form is refused; no response names the server",
       %{preview: p} do
    %URI{path: path, port: port} = URI.parse(p.url)

    for target <-
          ["http://127.0.0.1:#{port}#{path}", "HTTP://127.0.0.1#{path}events"] ++
            ["https://127.0.0.1#{path}", "*"] do
      head = raw(port, "GET #{target} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
      assert head =~ ~r/\AHTTP\/1\.1 400 /, target
    end

    assert raw(port, "GET #{path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n") =~ ~r/\AHTTP\/1\.1 200 /

    for url <- [p.url, p.url <> "preview.js", p.url <> "nothing", "http://127.0.0.1:#{port}/"] do
      {_, headers, _} = get(url)
      refute Map.has_key?(headers, "server"), url
    end

    {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false])
    :ok = :gen_tcp.send(sock, "GET #{path}events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    {:ok, head} = :gen_tcp.recv(sock, 0, 5_000)
    :gen_tcp.close(sock)
    assert head =~ "text/event-stream"
    refute head =~ ~r/^server:/im
  end

  test "a port in use, or not this machine's address, is said in words" do
    {:ok, taken} = :gen_tcp.listen(0, ip: {127, 0, 0, 1})
    {:ok, port} = :inet.port(taken)

    assert {:error, %RingTracer.Error{reason: :preview, message: m}} = Preview.start(port: port)

    assert m ==
             "port #{port} on 127.0.0.1 is in use (another program listens there): give another port, or 0 for a free one"

    # Another preview of this VM on that port.
    :gen_tcp.close(taken)
    {:ok, first} = Preview.start(port: port)
    assert {:error, %RingTracer.Error{message: ^m}} = Preview.start(port: port)
    Preview.stop(first, 0)

    for addr <- ["192.0.2.1", "10.255.255.254"] do
      log =
        ExUnit.CaptureLog.capture_log(fn ->
          assert {:error, %RingTracer.Error{reason: :preview, message: m}} =
                   Preview.start(listen: addr)

          assert m =~ addr and m =~ "not an address of this machine", m
          refute m =~ "{"
        end)

      # httpd's report of its failed start prints its configuration: the
      # page's secret is not in it (it was).
      refute log =~ ~r/"[\w-]{22}"/, log
    end

    err =
      capture_io(:stderr, fn ->
        {:ok, taken} = :gen_tcp.listen(port, ip: {127, 0, 0, 1})

        assert {:ok, _} =
                 RingTracer.render(@scene,
                   width: 8,
                   height: 8,
                   children: 2,
                   atoms: 2,
                   preview: port
                 )

        :gen_tcp.close(taken)
      end)

    assert err =~ "preview: port #{port} on 127.0.0.1 is in use"
  end

  # A client without the token that sends a request that never ends, one
  # byte each `every_ms`, and connects again whenever the preview cuts it
  # off, telling `to` how long each connection lasted.
  defp trickler(port, every_ms, to) do
    request =
      "GET /nothing HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Pad: " <> String.duplicate("a", 9_000)

    case :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false], 5_000) do
      {:ok, sock} ->
        t = System.monotonic_time(:millisecond)
        sent = trickle(sock, request, every_ms, 0)
        send(to, {:cut, System.monotonic_time(:millisecond) - t, sent})

      {:error, _} ->
        Process.sleep(every_ms)
    end

    trickler(port, every_ms, to)
  end

  defp trickle(sock, <<byte, rest::binary>>, every_ms, sent) do
    with :ok <- :gen_tcp.send(sock, <<byte>>),
         {:error, :timeout} <- :gen_tcp.recv(sock, 0, every_ms) do
      trickle(sock, rest, every_ms, sent + 1)
    else
      _ ->
        :gen_tcp.close(sock)
        sent
    end
  end

  # The deadline is 5 s; 2 s here, and the trickle and its bounds scaled to it.
  @tag request_deadline_s: 2
  test "a request trickled a byte at a time is cut off at one deadline", %{preview: p} do
    me = self()
    pid = spawn_link(fn -> trickler(p.port, 80, me) end)
    # Still sending, byte after byte, it is cut off 2 s after it connected
    # (httpd's one timer for the whole request; it was 60 s).
    assert_receive {:cut, ms, sent}, 9_000
    Process.unlink(pid)
    Process.exit(pid, :kill)
    assert ms >= 1_800 and ms < 7_000, "cut after #{ms} ms"
    assert sent >= 10
  end

  # The deadline is 2 s here (5 s by default): the loop below spans it.
  @tag request_deadline_s: 2
  test "clients that hold connections without the token do not keep the owner from the page",
       %{preview: p} do
    me = self()
    # 150 of them, each trickling a request that never ends and connecting
    # again as soon as it is cut off: far more than the 32 viewers.
    pids = for _ <- 1..150, do: spawn_link(fn -> trickler(p.port, 1_000, me) end)
    Process.sleep(1_500)

    try do
      # Over 4 s, through the deadline and the tricklers' reconnections, the
      # page and its stream answer every time (before: 503, heavy load).
      for _ <- 1..10 do
        assert {200, _, body} = get(p.url)
        assert body =~ ~s(<script src="preview.js">)

        {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, p.port, [:binary, active: false])
        path = URI.parse(p.url).path
        :ok = :gen_tcp.send(sock, "GET #{path}events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert {:ok, "HTTP/1.1 200 " <> _} = :gen_tcp.recv(sock, 0, 5_000)
        :gen_tcp.close(sock)
        Process.sleep(400)
      end

      # They were cut off, and came back.
      assert_received {:cut, _, _}
    after
      for pid <- pids do
        Process.unlink(pid)
        Process.exit(pid, :kill)
      end
    end
  end

  test "--listen widens: the page answers on the address given" do
    {:ok, p} = Preview.start(listen: "0.0.0.0")
    assert p.url =~ "http://0.0.0.0:"
    assert {200, _, _} = get(String.replace(p.url, "0.0.0.0", "127.0.0.1"))
    Preview.stop(p, 0)
  end

  test "two viewers during the job and one after it all get the whole job", %{preview: p} do
    check_viewers(p, :float)
  end

  test "a job in 8 bits is on the page as in floats", %{preview: p} do
    check_viewers(p, :srgb8)
  end

  defp check_viewers(p, format) do
    me = self()
    url = p.url <> "events"
    for i <- 1..2, do: spawn_link(fn -> send(me, {:viewer, i, Viewer.viewer(url)}) end)
    # The viewers are connected before the job starts.
    assert RingTracer.Test.Wait.eventually(fn -> Preview.viewers(p) == 2 end)

    {:ok, result} =
      RingTracer.render(@scene,
        width: 24,
        height: 16,
        children: 3,
        atoms: 4,
        preview: p,
        pixels: format
      )

    assert_receive {:viewer, 1, {:ok, n}}, 10_000
    assert_receive {:viewer, 2, {:ok, ^n}}, 10_000

    late = frames(p.url)
    assert length(late) == n
    assert Enum.map(late, &elem(&1, 0)) == Enum.to_list(1..n)
    names = Enum.map(late, &elem(&1, 1))
    assert hd(names) == "job" and Enum.take(names, -2) == ["final", "end"]

    atoms = for {_, "atom", a} <- late, do: a
    assert Enum.sort(Enum.map(atoms, & &1["a"])) == Enum.to_list(0..11)

    pixels =
      atoms
      |> Enum.sort_by(& &1["a"])
      |> Enum.map_join(&Base.decode64!(&1["px"]))

    assert pixels == RingTracer.Image.srgb8(result.pixels, result.pixel_format)
    assert byte_size(pixels) == 24 * 16 * 3

    for {_, "atom", a} <- late,
        do: assert(a["c"] == Enum.find(result.atoms, &(&1.atom == a["a"])).child)

    [{_, "final", final}] = for {_, "final", _} = f <- late, do: f
    assert final["ok"]
    assert Enum.map(final["children"], & &1["traced"]) == Enum.map(result.children, & &1.traced)

    # A browser reconnecting with Last-Event-ID gets only what it missed.
    resumed = frames(p.url, [{~c"last-event-id", ~c"#{n - 2}"}])
    assert Enum.map(resumed, &elem(&1, 1)) == ["final", "end"]
  end

  test "a job its caller could not describe (it had ended) is known from its start event",
       %{preview: p} do
    # The render's caller describes the parent right after starting it; on a
    # loaded machine the job may be over by then. The parent's start event
    # carries the same description.
    id = make_ref()
    :ok = GenServer.call(p.pid, {:expect, id, []})
    parent = spawn(fn -> receive(do: (:stop -> :ok)) end)

    info = %{
      id: id,
      t0: System.system_time(:microsecond),
      layout: RingTracer.Layout.new(8, 2, 2, 2),
      strategy: {RingTracer.Strategy.Ring, []},
      nodes: [node(), node()],
      speeds: [1, 1],
      results: %{},
      format: :float,
      traced_by: %{}
    }

    GenServer.cast(p.pid, {:described, parent, {:error, {:job_not_running, :noproc}}})
    send(p.pid, {:job_start, parent, id, info})
    send(parent, :stop)

    names = p.url |> frames() |> Enum.map(&elem(&1, 1))
    assert hd(names) == "job" and List.last(names) == "end"
  end

  test "a job that ends before the preview's server runs is on the page whole", %{preview: p} do
    # The server runs at low priority, after the job's processes: a short
    # job can end, and its parent exit, before the server gets to it. Here
    # the parent suspends it as the job starts, and it runs again once the
    # parent has exited.
    me = self()
    handler = {__MODULE__, :suspend, me}

    :ok =
      RingTracer.Telemetry.attach(
        handler,
        [:ring_tracer, :job, :start],
        fn _, _, _, {server, to} ->
          :erlang.suspend_process(server)
          send(to, {:parent, self()})
        end,
        {p.pid, me}
      )

    try do
      task =
        Task.async(fn ->
          RingTracer.render(@scene, width: 24, height: 16, children: 3, atoms: 4, preview: p)
        end)

      assert_receive {:parent, parent}, 10_000
      ref = Process.monitor(parent)
      assert_receive {:DOWN, ^ref, _, _, _}, 20_000
      # The render returned without the server.
      assert {:ok, result} = Task.await(task, 20_000)

      late = frames(p.url)
      names = Enum.map(late, &elem(&1, 1))
      assert hd(names) == "job" and Enum.take(names, -2) == ["final", "end"]
      atoms = for {_, "atom", a} <- late, do: a
      assert Enum.sort(Enum.map(atoms, & &1["a"])) == Enum.to_list(0..11)

      assert atoms |> Enum.sort_by(& &1["a"]) |> Enum.map_join(&Base.decode64!(&1["px"])) ==
               RingTracer.Image.srgb8(result.pixels)
    after
      RingTracer.Telemetry.detach(handler)
    end
  end

  test "a sequence: a late joiner gets its last image, a bounded strip of the last frames with their times" do
    check_sequence(strip: 3)
  end

  test "a sequence the preview lags far behind (its queued atoms of images complete dropped) ends the same" do
    check_sequence(strip: 3, cpu_share: 0.0001)
  end

  test "a sequence in 8 bits: the same strip and images" do
    check_sequence(strip: 3, pixels: :srgb8)
  end

  defp check_sequence(opts) do
    {format, opts} = Keyword.pop(opts, :pixels, :float)
    {:ok, p} = Preview.start(opts)
    on_exit(fn -> Preview.stop(p, 0) end)

    {:ok, job} =
      RingTracer.render_sequence("priv/scenes/whitted_orbit.toml",
        frames: 1..20,
        width: 16,
        height: 12,
        children: 2,
        preview: p,
        pixels: format
      )

    id = job.id
    frames = sequence_frames(id, %{})
    assert map_size(frames) == 20

    late = frames(p.url)
    names = Enum.map(late, &elem(&1, 1))
    assert hd(names) == "job" and Enum.take(names, -2) == ["final", "end"]
    [{_, "job", j}] = Enum.filter(late, &(elem(&1, 1) == "job"))
    assert {j["frames"], j["m"], j["total"], length(j["spans"])} == {20, 32, 640, 32}

    # The strip: the last 3 frames (in the order they completed: about,
    # not exactly, theirs), each with its time and its thumbnail.
    strip = for {_, "frame", f} <- late, do: f
    assert Enum.sort(Enum.map(strip, & &1["n"])) == [18, 19, 20]

    for f <- strip do
      assert f["us"] == RingTracer.Frame.elapsed_us(frames[f["n"]])
      assert f["f"] == f["n"] - 1
      assert Base.decode64!(f["px"]) == RingTracer.Image.srgb8(frames[f["n"]].pixels, format)
    end

    # Each: how many frames had completed, and their mean time.
    in_order = frames |> Map.values() |> Enum.sort_by(& &1.completed_us)

    for f <- strip do
      k = Enum.find_index(in_order, &(&1.number == f["n"])) + 1
      assert f["completed"] == k
      times = in_order |> Enum.take(k) |> Enum.map(&RingTracer.Frame.elapsed_us/1)
      assert f["mean_us"] == div(Enum.sum(times), k)
    end

    # The last image, whole: its release and its atoms, nothing of the others.
    assert for({_, "release", r} <- late, do: r["n"]) == [20]
    atoms = for {_, "atom", a} <- late, do: a
    assert Enum.sort(Enum.map(atoms, & &1["a"])) == Enum.to_list(608..639)

    assert atoms |> Enum.sort_by(& &1["a"]) |> Enum.map_join(&Base.decode64!(&1["px"])) ==
             RingTracer.Image.srgb8(frames[20].pixels, format)

    assert frames[20].pixel_format == format

    [{_, "final", final}] = for {_, "final", _} = f <- late, do: f
    assert final["ok"] and final["frames"] == 20
    assert Enum.all?(final["atoms"], &(&1["atom"] >= 17 * 32))
  end

  defp sequence_frames(id, frames) do
    receive do
      {RingTracer, ^id, {:frame, n, frame}} -> sequence_frames(id, Map.put(frames, n, frame))
      {RingTracer, ^id, {:progress, _, _}} -> sequence_frames(id, frames)
      {RingTracer, ^id, {:ok, _}} -> frames
      {RingTracer, ^id, {:error, error}} -> flunk(inspect(error))
    after
      60_000 -> flunk("the sequence did not end")
    end
  end

  test "protocol events and hand-overs of a slowed ring reach the page", %{preview: p} do
    {:ok, result} =
      RingTracer.render(@scene,
        width: 32,
        height: 24,
        children: 3,
        atoms: 6,
        speeds: [1, 40, 1],
        preview: p
      )

    late = frames(p.url)
    evs = for {_, "ev", e} <- late, do: e
    moves = for {_, "move", m} <- late, do: m
    assert length(evs) == length(result.events)

    assert Enum.sort(Enum.map(evs, & &1["kind"])) ==
             Enum.sort(Enum.map(result.events, &"#{&1.kind}"))

    assert Enum.sum(Enum.map(moves, & &1["n"])) ==
             Enum.sum(Enum.map(result.children, & &1.received))
  end

  test "a stalled viewer does not hold up the job", %{preview: p} do
    # A client that asks for the stream and never reads it.
    {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, p.port, [:binary, active: false, recbuf: 1024])

    :ok =
      :gen_tcp.send(
        sock,
        "GET #{URI.parse(p.url).path}events HTTP/1.1\r\nHost: localhost\r\n\r\n"
      )

    {:ok, result} =
      RingTracer.render(@scene, width: 160, height: 120, children: 2, atoms: 64, preview: p)

    assert length(result.atoms) == 128
    # The log is complete for others; the server holds nothing per viewer.
    assert length(frames(p.url)) >= 128 + 3
    {:message_queue_len, q} = Process.info(p.pid, :message_queue_len)
    assert q < 10
    :gen_tcp.close(sock)
  end

  # A client that asks for `url`'s stream and never reads it (a small
  # receive buffer, so that its connection is soon full).
  defp stalled_viewer(url) do
    %URI{port: port, path: path} = URI.parse(url)
    {:ok, sock} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false, recbuf: 1024])
    :ok = :gen_tcp.send(sock, "GET #{path}events HTTP/1.1\r\nHost: localhost\r\n\r\n")
    sock
  end

  @tag :tmp_dir
  test "viewers that never read hold up neither the render, nor its outputs, nor its end",
       %{tmp_dir: dir} do
    out = Path.join(dir, "big.png")
    me = self()
    handler = {__MODULE__, :job_end, me}

    :ok =
      RingTracer.Telemetry.attach(
        handler,
        [:ring_tracer, :job, :stop],
        fn _, _, _, pid -> send(pid, {:job_end, System.monotonic_time(:millisecond)}) end,
        me
      )

    try do
      capture_io(:stderr, fn ->
        # As soon as the render prints its page's address, 30 viewers ask
        # for the stream and never read it (a log of about 10 MB: far more
        # than their connections hold).
        stderr = Process.whereis(:standard_error)

        spawn_link(fn ->
          url =
            Stream.repeatedly(fn ->
              Process.sleep(5)
              Regex.run(~r|preview: (\S+)|, elem(StringIO.contents(stderr), 1))
            end)
            |> Enum.find(& &1)
            |> List.last()

          socks = for _ <- 1..30, do: stalled_viewer(url)
          # Theirs to keep open: a socket closes with its owner.
          Enum.each(socks, &(:ok = :gen_tcp.controlling_process(&1, me)))
          send(me, {:stalled, socks})
        end)

        argv =
          [
            @scene,
            "-o",
            out,
            "-w",
            "2400",
            "--height",
            "1600",
            "--children",
            "2",
            "--atoms",
            "32"
          ] ++
            ["--speeds", "4,4", "--progress", "none", "--preview"]

        capture_io(fn -> assert :ok = RingTracer.CLI.Render.execute(argv) end)
        done = System.monotonic_time(:millisecond)
        assert_received {:stalled, socks}
        assert_received {:job_end, ended}
        send(me, {:times, ended, done, socks})
      end)

      assert_received {:times, ended, done, socks}
      # The image is written, and the command returned, without waiting on
      # any of them (it took 6 s: 2 s of a drain that waited on them, then
      # 4 s of httpd's shutdown of their connections' processes, blocked in
      # a send that had no deadline).
      assert File.exists?(out)
      assert done - ended < 3_000, "#{done - ended} ms from the job's end to the command's"

      # Each was disconnected: past what its connection held, it reads the end.
      for sock <- socks, do: assert(drain(sock) == :closed)
    after
      RingTracer.Telemetry.detach(handler)
    end
  end

  test "a viewer that stops reading is disconnected; one that reads gets everything",
       %{preview: p} do
    me = self()
    stalled = stalled_viewer(p.url)
    spawn_link(fn -> send(me, {:reader, Viewer.viewer(p.url <> "events", 60_000)}) end)
    assert RingTracer.Test.Wait.eventually(fn -> Preview.viewers(p) == 2 end)

    # A log of about 15 MB, far more than the stalled viewer's connection
    # holds: its process has a chunk waiting, and the send's deadline.
    {:ok, _} =
      RingTracer.render(@scene, width: 2400, height: 1600, children: 2, atoms: 32, preview: p)

    assert_receive {:reader, {:ok, n}}, 60_000
    assert n == length(frames(p.url))
    # Dropped by the preview, which still runs (before: it stayed a viewer
    # until the preview stopped).
    assert RingTracer.Test.Wait.eventually(fn -> Preview.viewers(p) == 0 end, 1_000)
    assert drain(stalled) == :closed
    assert {200, _, _} = get(p.url)
  end

  defp drain(sock) do
    case :gen_tcp.recv(sock, 0, 5_000) do
      {:ok, _} -> drain(sock)
      {:error, reason} -> reason
    end
  end

  test "open/2 previews a job already running, from the atoms traced so far" do
    # The first atom is held until the preview has opened, so that the job
    # is still running then however late a loaded machine lets this test
    # act (slowed down to about a second, it had once ended before).
    ref = make_ref()

    {:ok, job} =
      RingTracer.render_async(@scene,
        width: 160,
        height: 120,
        children: 2,
        atoms: 8,
        kernel: {RingTracer.Test.FaultyKernel, block_first: {node(), self(), ref}}
      )

    id = job.id
    assert_receive {:blocked, ^ref, held}, 20_000
    assert_receive {RingTracer, ^id, {:progress, done, _}} when done >= 2, 20_000
    {:ok, p} = Preview.open(job)
    send(held, {:release, ref})
    assert_receive {RingTracer, ^id, {:ok, result}}, 60_000

    late = frames(p.url)
    atoms = for {_, "atom", a} <- late, do: a
    assert Enum.sort(Enum.map(atoms, & &1["a"])) == Enum.to_list(0..15)
    # Those traced before it opened carry no arrival time.
    assert Enum.any?(atoms, &(&1["at"] == nil))
    assert length(result.atoms) == 16
    Preview.stop(p, 0)

    assert {:error, %RingTracer.Error{reason: :preview}} = Preview.open(job)
  end

  test "render/2 with preview: true prints the address and stops the page at the end" do
    err =
      capture_io(:stderr, fn ->
        assert {:ok, _} =
                 RingTracer.render(@scene,
                   width: 8,
                   height: 8,
                   children: 2,
                   atoms: 2,
                   preview: true
                 )
      end)

    assert [_, url, port] = Regex.run(~r|preview: (http://127\.0\.0\.1:(\d+)/[\w-]{22}/)|, err)
    # Stopped when render/2 returns: no socket of this VM listens on the
    # port any more, and nothing there serves the page (the port is free
    # again: another program on this machine may have bound it since).
    port = String.to_integer(port)
    assert listeners(port) == []
    refute serves_page?(url)
  end

  test "stop/1 returns once the listening socket is closed, however late httpd's socket owner runs",
       %{preview: p} do
    # httpd's listening socket belongs to a process outside its supervision
    # tree that closes it once it runs after the acceptor's exit: under load
    # that can be after the httpd is gone. Here it does not run at all.
    [{_, {:connected, owner}}] = listeners(p.port)
    :erlang.suspend_process(owner)

    try do
      Preview.stop(p, 0)
      assert listeners(p.port) == []
      refute serves_page?(p.url)
    after
      :erlang.resume_process(owner)
    end
  end

  test "a preview pacing its work answers a stop at once, before its job ends" do
    # Each atom's work is followed by a pause 999 times as long: the events
    # queue up, and the stop must not wait behind them.
    {:ok, p} = Preview.start(cpu_share: 0.001)

    {:ok, job} =
      RingTracer.render_async(@scene,
        width: 160,
        height: 120,
        children: 2,
        atoms: 8,
        speeds: [1000, 1000],
        preview: p
      )

    id = job.id
    assert_receive {RingTracer, ^id, {:progress, done, _}} when done >= 3, 30_000
    Preview.stop(p, 0)
    refute_received {RingTracer, ^id, {:ok, _}}
    assert listeners(p.port) == []
    assert_receive {RingTracer, ^id, {:ok, result}}, 60_000
    assert length(result.atoms) == 16
  end

  test "a job that dies while atoms are queued: the page gets them, then the end" do
    {:ok, p} = Preview.start(cpu_share: 0.001)

    {:ok, job} =
      RingTracer.render_async(@scene,
        width: 160,
        height: 120,
        children: 2,
        atoms: 8,
        speeds: [1000, 1000],
        preview: p
      )

    id = job.id
    assert_receive {RingTracer, ^id, {:progress, done, _}} when done >= 3, 30_000

    [parent] =
      for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Names.jobs()), do: pid

    Process.exit(parent, :kill)
    assert_receive {RingTracer, ^id, {:error, _}}, 10_000

    late = frames(p.url)
    assert length(for {_, "atom", _} <- late, do: 1) >= done
    assert [{_, "final", %{"ok" => false}}, {_, "end", _}] = Enum.take(late, -2)
    Preview.stop(p, 0)
  end

  @tag :tmp_dir
  test "ringtracer render --preview [PORT] serves the page while it renders", %{tmp_dir: dir} do
    out = Path.join(dir, "p.png")

    for args <- [["--preview"], ["--preview", "0"], ["--preview", "--quiet"]] do
      err =
        capture_io(:stderr, fn ->
          capture_io(fn ->
            argv =
              [@scene, "-o", out, "-w", "16", "--children", "2", "--progress", "none"] ++ args

            assert :ok = RingTracer.CLI.Render.execute(argv)
          end)
        end)

      assert err =~ ~r|preview: http://127\.0\.0\.1:\d+/[\w-]{22}/|, inspect(args)
    end

    assert {:error, 2, message} =
             RingTracer.CLI.Render.execute([@scene, "-o", out, "--preview", "70000"])

    assert message =~ "--preview takes an integer from 0 to 65535"
  end

  # The timeout covers the scene's loading and the preview's start: 3 s leaves them time on a
  # loaded machine (200 ms once did not: the render timed out before the preview started),
  # and the image, every atom slowed a thousandfold, takes far longer.
  test "a preview render/2 started goes with it when the render times out" do
    err =
      capture_io(:stderr, fn ->
        assert {:error, %RingTracer.Error{reason: :timeout}} =
                 RingTracer.render("priv/scenes/balls_s1.nff",
                   width: 320,
                   height: 240,
                   children: 2,
                   atoms: 8,
                   speeds: [1000, 1000],
                   timeout: 3_000,
                   preview: true
                 )
      end)

    [_, url, port] = Regex.run(~r|preview: (http://127\.0\.0\.1:(\d+)/[\w-]{22}/)|, err)
    port = String.to_integer(port)
    assert RingTracer.Test.Wait.eventually(fn -> listeners(port) == [] end)
    refute serves_page?(url)
  end

  test "the :preview option is checked" do
    for bad <- [-1, 70_000, "yes", [port: "x"], [listen: "nowhere"], [bogus: 1], [strip: 0]] do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: m}} =
               RingTracer.render(@scene, preview: bad)

      assert m =~ ":preview"
    end
  end
end
