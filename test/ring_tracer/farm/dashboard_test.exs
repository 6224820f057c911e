defmodule RingTracer.Farm.DashboardTest do
  # The farm's dashboard on a head with one worker (a peer): its address and
  # token, what it refuses, its JSON, a running job's preview link, the
  # same address after the head restarts, and (`:browser`) a headless
  # chromium that sees the worker, the job and the link, with a hostile
  # user name shown as text.
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 240_000

  alias RingTracer.{Farm, Names}
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.{CDP, Wait}
  alias RingTracer.TestScenes

  # A user name that is markup, and one that is not UTF-8.
  @hostile ~s(<img src=x onerror="document.body.dataset.pwned='1'">&amp;)
  # A job that keeps its ring busy until cancelled.
  @slow [
    width: 64,
    height: 48,
    kernel: {RingTracer.Kernel.Simulated, costs: 60_000},
    atoms: 8,
    frames: 1..48
  ]

  setup_all do
    Peers.ensure_distributed()
    {:ok, _} = Application.ensure_all_started(:inets)
    {p, n} = Peers.start("dw1")
    on_exit(fn -> Peers.stop(p) end)
    {:ok, peer: {p, n}}
  end

  setup %{peer: {p, n}} do
    dir = Path.join(System.tmp_dir!(), "rt_dash_#{System.unique_integer([:positive])}")
    {:ok, _} = Farm.start_head(dir: dir, dashboard: true)
    {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 1, speed: 2]])
    assert Wait.eventually(fn -> length(elem(Farm.workers(node()), 1)) == 1 end, 500)
    {:ok, url} = Farm.dashboard_url()

    on_exit(fn ->
      :ok = Peers.call(p, n, Farm, :leave, [])
      Farm.stop_head()
      File.rm_rf!(dir)
    end)

    {:ok, url: url, worker: n}
  end

  # A connection per request (see the preview's HTTP test).
  defp get(url, headers \\ [], method \\ :get) do
    headers = [{~c"connection", ~c"close"} | headers]

    {:ok, {{_, code, _}, head, body}} =
      :httpc.request(method, {String.to_charlist(url), headers}, [autoredirect: false], [])

    # the body's bytes (a list of bytes, not of characters)
    {code, Map.new(head, fn {k, v} -> {to_string(k), to_string(v)} end),
     IO.iodata_to_binary(body)}
  end

  defp state(url) do
    {200, head, body} = get(url <> "state.json")
    assert head["content-type"] =~ "application/json"
    {body, :jiffy.decode(body, [:return_maps, :use_nil])}
  end

  defp submit(user) do
    {:ok, id} = Farm.submit(node(), TestScenes.path("whitted_orbit.toml"), @slow ++ [user: user])
    id
  end

  test "on loopback, under a token: the page and state.json; nothing without the token", %{
    url: url
  } do
    assert %URI{scheme: "http", host: "127.0.0.1", port: port, path: "/" <> path} = URI.parse(url)

    [token, ""] = String.split(path, "/")
    assert byte_size(token) >= 22

    for file <- ["", "index.html", "dashboard.js", "dashboard.css", "state.json"] do
      {code, head, _} = get(url <> file)
      assert code == 200, file
      refute Map.has_key?(head, "server")
      assert head["content-security-policy"] =~ "default-src 'self'"
      assert head["cache-control"] == "no-store"
    end

    root = "http://127.0.0.1:#{port}/"

    for path <- ["", "index.html", "state.json", "x/state.json", token, "#{token}x/state.json"],
        do: assert({404, _, _} = get(root <> path), path)

    assert {404, _, _} = get(url <> "nothing")
    assert {404, _, _} = get(url <> "../dashboard.js")
    assert {405, _, _} = get(url <> "state.json", [], :delete)
    # A page that rebound a name of its own to 127.0.0.1.
    assert {421, _, _} = get(url <> "state.json", [{~c"host", ~c"evil.example"}])

    # Nothing answers on this machine's other addresses.
    {:ok, ifs} = :inet.getifaddrs()

    for {_, opts} <- ifs,
        addr <- Keyword.get_values(opts, :addr),
        tuple_size(addr) == 4 and addr != {127, 0, 0, 1} do
      assert {:error, _} = :gen_tcp.connect(addr, port, [], 1_000)
    end
  end

  test "state.json: workers, jobs, the queue, a running job's preview; user strings escaped", %{
    url: url,
    worker: worker
  } do
    a = submit(@hostile)
    b = submit(<<"bob", 0xFF>>)

    # a runs on the one worker and has its preview; b waits.
    assert Wait.eventually(
             fn ->
               {_, view} = state(url)
               job = Enum.find(view["jobs"], &(&1["id"] == a))
               job["state"] == "running" and is_binary(job["preview"])
             end,
             1_000
           )

    {body, view} = state(url)
    # The markup reaches the page as JSON text only: no raw <, > or &.
    refute body =~ ~r/[<>&]/
    assert body =~ "\\u003cimg"

    assert view["head"] == Atom.to_string(node())
    assert is_integer(view["now"])

    assert [w] = view["workers"]

    assert Map.take(w, ["node", "state", "job", "speed", "slots", "tags"]) == %{
             "node" => Atom.to_string(worker),
             "state" => "working",
             "job" => a,
             "speed" => 2,
             "slots" => 1,
             "tags" => []
           }

    [ja, jb] = Enum.filter(view["jobs"], &(&1["id"] in [a, b]))
    assert ja["user"] == @hostile
    assert jb["user"] == "bob\uFFFD"
    assert {ja["scene"], ja["frames"], ja["workers"]} == {"whitted_orbit.toml", 48, [w["node"]]}
    assert ja["done"] <= ja["frames"] and ja["progress"] >= 0 and ja["progress"] <= 1
    assert {jb["state"], jb["preview"], jb["time_left"]} == {"queued", nil, nil}
    assert view["queue"] == [b]

    # The preview link is the job's live page, on loopback, with its own token.
    preview = ja["preview"]
    assert preview =~ ~r"\Ahttp://127\.0\.0\.1:\d+/[A-Za-z0-9_-]{22}/\z"
    refute String.starts_with?(preview, url)
    assert {200, _, page} = get(preview)
    assert page =~ "live preview"

    # Once the ring has traced an atom, a time left.
    assert Wait.eventually(
             fn ->
               {_, view} = state(url)
               is_integer(Enum.find(view["jobs"], &(&1["id"] == a))["time_left"])
             end,
             2_000
           )

    :ok = Farm.cancel(node(), a)
    :ok = Farm.cancel(node(), b)

    # Ended: no preview, which has stopped.
    {_, view} = state(url)
    assert Enum.find(view["jobs"], &(&1["id"] == a))["preview"] == nil

    assert Wait.eventually(
             fn ->
               match?(
                 {:error, _},
                 :httpc.request(:get, {String.to_charlist(preview), []}, [], [])
               )
             end,
             500
           )
  end

  test "the address stays the same when the head restarts", %{url: url} do
    head = Process.whereis(Names.farm_head())
    ref = Process.monitor(head)
    Process.exit(head, :kill)
    assert_receive {:DOWN, ^ref, _, _, _}, 5_000

    assert Wait.eventually(
             fn ->
               new = Process.whereis(Names.farm_head())
               new != nil and new != head
             end,
             500
           )

    assert Farm.dashboard_url() == {:ok, url}
    assert Wait.eventually(fn -> match?({200, _, _}, get(url <> "state.json")) end, 500)
  end

  test "bad options and a port in use are refused, in words" do
    dir = Path.join(System.tmp_dir!(), "rt_dash_bad_#{System.unique_integer([:positive])}")

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             Farm.start_head(dir: dir, dashboard: :yes)

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             Farm.start_head(dir: dir, dashboard: [port: 70_000])

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             Farm.start_head(dir: dir, dashboard: [listen: "nowhere"])

    assert {:error, %RingTracer.Error{reason: :farm}} = Farm.dashboard_url(:nohead@localhost)
  end

  test "a port in use is said in words, and the head does not start" do
    Farm.stop_head()
    {:ok, socket} = :gen_tcp.listen(0, ip: {127, 0, 0, 1})
    {:ok, port} = :inet.port(socket)
    dir = Path.join(System.tmp_dir!(), "rt_dash_port_#{System.unique_integer([:positive])}")

    try do
      assert {:error, %RingTracer.Error{reason: :farm, message: message}} =
               Farm.start_head(dir: dir, dashboard: [port: port])

      assert message =~ "dashboard: port #{port} on 127.0.0.1 is in use"
      assert Process.whereis(Names.farm_head()) == nil
    after
      :gen_tcp.close(socket)
      File.rm_rf!(dir)
    end
  end

  describe "in a browser" do
    setup do
      {:ok, chromium: chromium()}
    end

    @tag :browser
    @tag :tmp_dir
    test "chromium sees the worker, the job with its preview link, and the user as text", %{
      url: url,
      worker: worker,
      chromium: chromium,
      tmp_dir: dir
    } do
      if chromium == nil do
        IO.puts(:stderr, "\nskipped: chromium is not installed and apt-get could not install it")
      else
        id = submit(@hostile)
        cdp = CDP.start(chromium, url, Path.join(dir, "profile"))

        try do
          cdp =
            CDP.await(
              cdp,
              "document.body.dataset.state === 'live' && " <>
                "document.querySelector('tr.job[data-id=\"#{id}\"] a.preview') !== null",
              60_000
            )

          {nodes, cdp} =
            CDP.eval(
              cdp,
              "[...document.querySelectorAll('tr.worker .node')].map(e => e.textContent)"
            )

          assert nodes == [Atom.to_string(worker)]

          {[user, state, href], cdp} =
            CDP.eval(
              cdp,
              "(r => [r.querySelector('.user').textContent, r.querySelector('.state-running') && " <>
                "r.querySelector('.state-running').textContent, r.querySelector('a.preview').href])" <>
                "(document.querySelector('tr.job[data-id=\"#{id}\"]'))"
            )

          assert user == @hostile
          assert state == "running"
          {:ok, info} = Farm.status(node(), id)
          assert href == info.preview

          # The markup stayed text: no image made, no handler run.
          {injected, cdp} =
            CDP.eval(
              cdp,
              "[document.querySelectorAll('img').length, document.body.dataset.pwned === undefined]"
            )

          assert injected == [0, true]

          {shot, cdp} = CDP.screenshot(cdp)
          assert <<0x89, "PNG", _::binary>> = shot

          if out = System.get_env("PREVIEW_SCREENSHOTS"),
            do: File.write!(Path.join(out, "farm-dashboard.png"), shot)

          CDP.stop(cdp)
        after
          Farm.cancel(node(), id)
        end
      end
    end
  end

  defp chromium do
    case System.find_executable("chromium") do
      nil ->
        if System.find_executable("apt-get") do
          System.cmd("apt-get", ["install", "-y", "-qq", "chromium"],
            env: [{"DEBIAN_FRONTEND", "noninteractive"}],
            stderr_to_stdout: true
          )
        end

        System.find_executable("chromium")

      path ->
        path
    end
  end
end
