defmodule RingTracer.Cluster.ForeignEpmdTest do
  # A second Unix user starts an epmd of hers on 127.0.0.1:4369 before any
  # other (in a network namespace of this test's own, so no other test's
  # epmd is disturbed). Hers answers every port query with a relay that
  # forwards to the real node and prints what passes through it. Then a
  # worker and a render start there, as the launcher boots them.
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag :tmp_dir
  @moduletag timeout: 240_000

  alias RingTracer.Cluster.{Cookie, TLS}
  alias RingTracer.Test.{OSNode, SecondUser}

  @attacker "rtdistevil"
  @scene Path.expand("priv/scenes/balls_s2.nff")

  setup_all do
    case System.cmd("id", ["-u"]) do
      {"0\n", 0} -> :ok
      _ -> flunk("needs root: it creates a second user and a network namespace")
    end

    :ok = SecondUser.ensure(@attacker)
    ns = "rtdist_#{System.unique_integer([:positive])}"
    {_, 0} = System.cmd("ip", ["netns", "add", ns], stderr_to_stdout: true)
    on_exit(fn -> remove_namespace(ns) end)
    {_, 0} = System.cmd("ip", ["netns", "exec", ns, "ip", "link", "set", "lo", "up"])
    fake = start_fake_epmd(ns)
    {:ok, ns: ns, fake: fake, uid: uid()}
  end

  # Every process still in the namespace (her epmd, under runuser, among
  # them) is killed by its id, then the namespace goes.
  defp remove_namespace(ns) do
    {pids, _} = System.cmd("ip", ["netns", "pids", ns], stderr_to_stdout: true)

    for pid <- String.split(pids),
        do: System.cmd("kill", ["-KILL", pid], stderr_to_stdout: true)

    System.cmd("ip", ["netns", "del", ns], stderr_to_stdout: true)
  end

  setup %{tmp_dir: dir} do
    cookie = Path.join(dir, "cookie")
    {:ok, _} = Cookie.create(cookie)
    {:ok, cookie: cookie}
  end

  defp uid do
    {id, 0} = System.cmd("id", ["-u", @attacker])
    String.trim(id)
  end

  # Her epmd, as her, in the namespace: nothing else listens on 4369 there
  # yet. A process of its own owns the port and keeps all it printed.
  defp start_fake_epmd(ns) do
    test = self()
    collector = spawn(fn -> collect(ns, test) end)

    receive do
      {:fake_epmd, :listening} -> collector
    after
      60_000 -> flunk("her epmd did not start: #{inspect(output(collector))}")
    end
  end

  defp collect(ns, test) do
    erl = System.find_executable("erl")
    paths = Enum.flat_map(OSNode.code_paths(), &["-pa", &1])

    port =
      Port.open({:spawn_executable, System.find_executable("ip")}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args:
          ["netns", "exec", ns, "runuser", "-u", @attacker, "--", erl, "-noshell"] ++
            paths ++ ["-s", "Elixir.RingTracer.Test.FakeEpmd", "main"]
      ])

    collect_loop(port, test, "")
  end

  defp collect_loop(port, test, output) do
    receive do
      {^port, {:data, data}} ->
        output = output <> data
        if output =~ "LISTENING", do: send(test, {:fake_epmd, :listening})
        collect_loop(port, test, output)

      {^port, {:exit_status, _}} ->
        collect_loop(nil, test, output)

      {:output, from} ->
        send(from, {:fake_epmd, output})
        collect_loop(port, test, output)
    end
  end

  defp output(collector) do
    send(collector, {:output, self()})

    receive do
      {:fake_epmd, output} -> output
    after
      5_000 -> ""
    end
  end

  # What her epmd printed since `from` (bytes of output), after a moment
  # for the last lines to arrive.
  defp seen(fake, from) do
    Process.sleep(500)
    all = output(fake)
    binary_part(all, from, byte_size(all) - from)
  end

  # The bytes relayed, one binary per connection and direction.
  defp relayed(lines) do
    for line <- String.split(lines, "\n"),
        ["DATA", id, dir, data] <- [String.split(line, " ")],
        reduce: %{} do
      acc -> Map.update(acc, {id, dir}, Base.decode64!(data), &(&1 <> Base.decode64!(data)))
    end
  end

  defp in_ns(ns, args, vm_args),
    do: OSNode.start(args, prefix: ["ip", "netns", "exec", ns], vm_args: vm_args)

  defp tls, do: TLS.vm_args(TLS.booted_dir())

  defp name(tag), do: "rtdist_#{tag}_#{System.unique_integer([:positive])}"

  defp render_args(worker, cookie, dir) do
    [
      "render",
      @scene,
      "-o",
      Path.join(dir, "out.png"),
      "--nodes",
      "#{worker}@localhost",
      "--cookie-file",
      cookie,
      "--children",
      "4",
      "--width",
      "48",
      "--progress",
      "none"
    ]
  end

  # A piece of the scene's text, which a reader of the stream would see.
  # What a job says of its scene in the clear: its file's name (the scene's
  # contents travel compressed, to a node that lacks them).
  defp scene_text, do: Path.basename(@scene)

  test "with plain distribution her epmd is refused, naming her", %{ns: ns, cookie: cookie} do
    {status, output} =
      OSNode.wait_exit(
        in_ns(
          ns,
          ["worker", "--sname", name("p"), "--cookie-file", cookie, "--insecure-plain"],
          []
        )
      )

    assert status == 1
    assert output =~ "epmd (port 4369) belongs to user #{@attacker}"
    assert output =~ "--allow-foreign-epmd"
  end

  test "--listen 0.0.0.0 with an epmd on loopback only is an error, not silence", %{
    ns: ns,
    cookie: cookie
  } do
    {status, output} =
      OSNode.wait_exit(
        in_ns(
          ns,
          ["worker", "--sname", name("any"), "--cookie-file", cookie, "--listen", "0.0.0.0"],
          tls()
        )
      )

    assert status == 1
    assert output =~ "epmd runs but does not listen on every address (--listen 0.0.0.0)"
  end

  test "over TLS (the default) she is warned about, and her relay carries only ciphertext", %{
    ns: ns,
    fake: fake,
    uid: uid,
    cookie: cookie,
    tmp_dir: dir
  } do
    from = byte_size(output(fake))
    w = name("w")
    worker = in_ns(ns, ["worker", "--sname", w, "--cookie-file", cookie], tls())
    on_exit(fn -> OSNode.stop(worker) end)
    {:ok, worker} = OSNode.await(worker, "ready", 60_000)
    warning = "warning: epmd (port 4369) belongs to user #{@attacker} (uid #{uid}) on 127.0.0.1"
    assert worker.output =~ warning

    {status, output} = OSNode.wait_exit(in_ns(ns, render_args(w, cookie, dir), tls()), 120_000)
    assert status == 0, output
    assert output =~ warning
    assert output =~ "on #{w}@localhost"

    lines = seen(fake, from)
    assert lines =~ "REGISTERED #{w}"
    streams = relayed(lines)
    # She was in the middle of the render's connection to the worker ...
    assert map_size(streams) > 0

    for {{_, "to"}, bytes} <- streams do
      # ... and saw a TLS handshake (a record of type 22), then ciphertext.
      assert <<22, 3, _::binary>> = bytes
      refute bytes =~ scene_text()
      refute bytes =~ w
    end

    for {_, bytes} <- streams, do: refute(bytes =~ "rtdist_")
  end

  test "the relay does read plain distribution (with --allow-foreign-epmd), so the test above can fail",
       %{ns: ns, fake: fake, cookie: cookie, tmp_dir: dir} do
    from = byte_size(output(fake))
    w = name("pw")
    plain = ["--insecure-plain", "--allow-foreign-epmd"]
    worker = in_ns(ns, ["worker", "--sname", w, "--cookie-file", cookie | plain], [])
    on_exit(fn -> OSNode.stop(worker) end)
    {:ok, worker} = OSNode.await(worker, "ready", 60_000)
    assert worker.output =~ "can read and alter everything this node says"

    {status, output} =
      OSNode.wait_exit(in_ns(ns, render_args(w, cookie, dir) ++ plain, []), 120_000)

    assert status == 0, output
    lines = seen(fake, from)
    to_worker = for {{_, "to"}, bytes} <- relayed(lines), into: "", do: bytes
    assert to_worker =~ w
    assert to_worker =~ scene_text()
  end
end
