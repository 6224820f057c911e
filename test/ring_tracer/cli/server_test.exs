defmodule RingTracer.CLI.ServerTest do
  # `ringtracer serve` and the launcher's client, as users run them: real OS
  # processes, from another folder, interrupted with real signals.
  use ExUnit.Case, async: true

  import RingTracer.Test.PortOutput, only: [collect: 1, until: 2]

  alias RingTracer.CLI.Server

  @moduletag :distributed
  @moduletag timeout: 240_000
  @launcher Path.expand("bin/ringtracer")

  doctest RingTracer.CLI.Server.Session

  setup_all do
    dir =
      Path.join(System.tmp_dir!(), "rt_serve_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")

    scenes = Path.join(dir, "scenes")
    File.mkdir_p!(scenes)
    File.cp!("priv/scenes/balls_s2.nff", Path.join(scenes, "mine.nff"))
    socket = Path.join([dir, "run", "serve.sock"])
    on_exit(fn -> File.rm_rf!(dir) end)

    # The server's port belongs to a process that lives as long as the tests.
    test_pid = self()

    holder =
      spawn(fn ->
        send(test_pid, {:server, open(["serve"], dir, [{"RINGTRACER_SOCKET", socket}])})

        receive do
          {:stop, from, server} -> send(from, {:stopped, stop(server)})
        end
      end)

    server = receive do: ({:server, server} -> server)
    wait_for(socket, 600)

    on_exit(fn ->
      send(holder, {:stop, self(), server})
      receive do: ({:stopped, _} -> :ok), after: (15_000 -> :ok)
    end)

    {:ok, dir: dir, scenes: scenes, socket: socket, server: server}
  end

  # `umask`: the launcher runs under that umask (through sh), else the test VM's.
  defp open(args, cd, env, umask \\ nil) do
    {exe, args} =
      if umask,
        do: {"/bin/sh", ["-c", "umask #{umask} && exec \"$0\" \"$@\"", @launcher | args]},
        else: {@launcher, args}

    port =
      Port.open({:spawn_executable, exe}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: args,
        cd: cd,
        env: for({k, v} <- env, do: {String.to_charlist(k), String.to_charlist(v)})
      ])

    {:os_pid, pid} = Port.info(port, :os_pid)
    {port, pid}
  end

  defp wait_for(_path, 0), do: flunk("ringtracer serve did not start")

  defp wait_for(path, n) do
    unless File.exists?(path) do
      Process.sleep(50)
      wait_for(path, n - 1)
    end
  end

  defp stop({port, pid}) do
    System.cmd("kill", ["-TERM", "#{pid}"])

    receive do
      {^port, {:exit_status, _}} -> :ok
    after
      10_000 -> System.cmd("kill", ["-KILL", "#{pid}"])
    end
  end

  defp served(ctx, args),
    do: open(args, ctx.scenes, [{"RINGTRACER_SOCKET", ctx.socket}, {"RINGTRACER_SERVER", "only"}])

  defp auto(ctx, args), do: open(args, ctx.scenes, [{"RINGTRACER_SOCKET", ctx.socket}])
  defp own_vm(ctx, args), do: open(args, ctx.scenes, [{"RINGTRACER_SERVER", "off"}])

  defp run(opened) do
    {port, _} = opened
    collect(port)
  end

  test "renders from the caller's folder, the same image as a VM of its own", ctx do
    args = ~w(render mine.nff --width 64 --atoms 8)
    {0, out} = run(served(ctx, args ++ ~w(-o served.png)))
    {0, own} = run(own_vm(ctx, args ++ ~w(-o own.png)))
    assert out =~ "wrote #{Path.join(ctx.scenes, "served.png")} (64x64)"
    assert out =~ ~r/rays: \d+ .*Mrays\/s/
    assert own =~ "own.png (64x64)"

    assert File.read!(Path.join(ctx.scenes, "served.png")) ==
             File.read!(Path.join(ctx.scenes, "own.png"))
  end

  test "a served render's new files get the caller's umask, as in a VM of its own", ctx do
    args = ~w(render mine.nff --width 32 --atoms 4)
    env = [{"RINGTRACER_SOCKET", ctx.socket}, {"RINGTRACER_SERVER", "only"}]
    mode = fn name -> Bitwise.band(File.stat!(Path.join(ctx.scenes, name)).mode, 0o777) end

    for {umask, want} <- [{"077", 0o600}, {"002", 0o664}] do
      outs = ~w(-o u#{umask}.png --stats u#{umask}.json --timeline u#{umask}.svg)
      {0, out} = run(open(args ++ outs, ctx.scenes, env, umask))
      assert out =~ "wrote"

      {0, _} =
        run(
          open(args ++ ~w(-o own#{umask}.png), ctx.scenes, [{"RINGTRACER_SERVER", "off"}], umask)
        )

      for name <- ~w(u#{umask}.png u#{umask}.json u#{umask}.svg own#{umask}.png),
          do: assert(mode.(name) == want, "#{name}: #{Integer.to_string(mode.(name), 8)}")
    end

    # a file replaced keeps its permissions, whoever's umask
    File.chmod!(Path.join(ctx.scenes, "u077.json"), 0o640)
    {0, _} = run(open(args ++ ~w(-o u077.png --stats u077.json), ctx.scenes, env, "000"))
    assert {mode.("u077.png"), mode.("u077.json")} == {0o600, 0o640}
  end

  test "help, usage errors and failures: the same text and status as a VM of its own", ctx do
    for args <- [
          ~w(render --help),
          ~w(render mine.nff -o x.png --childs 4),
          ~w(render mine.nff -o x.png --children abc),
          ~w(render missing.nff -o x.png)
        ] do
      {status, out} = run(served(ctx, args))
      assert {status, out} == run(own_vm(ctx, args)), Enum.join(args, " ")
      assert status in [0, 1, 2]
    end
  end

  test "a render on other nodes boots a VM of its own", ctx do
    # Distribution is the command's own VM's to start: the same error.
    args = ~w(render mine.nff -o x.png --nodes nobody@nowhere --cookie-file missing-cookie)
    {status, out} = run(auto(ctx, args))
    assert {status, out} == run(own_vm(ctx, args))
    assert status != 0
    # Told to use only the server, it says why it cannot.
    {1, out} = run(served(ctx, args))
    assert out =~ "cannot take this command"
  end

  for {signal, status} <- [{"INT", 130}, {"TERM", 143}] do
    test "SIG#{signal} cancels the served render: status #{status}, no file, the server goes on",
         ctx do
      {port, pid} =
        served(ctx, ~w(render mine.nff -o slow.png --width 256 --speeds 400 --progress bar))

      until(port, "atoms")
      {_, 0} = System.cmd("kill", ["-#{unquote(signal)}", "#{pid}"])
      {status, out} = collect(port)

      assert status == unquote(status), out
      assert out =~ ~r/interrupted|terminated/
      assert Enum.filter(File.ls!(ctx.scenes), &String.contains?(&1, "slow")) == []
      {ps, _} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{pid}"])
      assert String.trim(ps) == ""
      assert {0, _} = run(served(ctx, ~w(render mine.nff -o after.png --width 16)))
    end
  end

  test "a client killed outright cancels its job", ctx do
    args = ~w(render mine.nff --width 96 --speeds 200 --progress bar)
    # How long the job takes when nothing stops it.
    t0 = System.monotonic_time(:millisecond)
    {0, _} = run(served(ctx, args ++ ~w(-o whole.png)))
    whole_ms = System.monotonic_time(:millisecond) - t0

    {port, pid} = served(ctx, args ++ ~w(-o killed.png))
    until(port, "atoms")
    # The launcher's client, killed as a second Ctrl-C would.
    {client, 0} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{pid}"])
    {_, 0} = System.cmd("kill", ["-KILL", String.trim(client)])
    {status, _out} = collect(port)
    assert status != 0

    # A job that went on would have written its image by now.
    Process.sleep(whole_ms + 2_000)
    refute File.exists?(Path.join(ctx.scenes, "killed.png"))
  end

  # A second server of the tests' own, on a socket of its own, whose VM the
  # test may stop (SIGSTOP): its OS pid is the launcher's child.
  defp own_server(ctx, name) do
    socket = Path.join([ctx.dir, name, "serve.sock"])
    {port, launcher} = open(["serve"], ctx.dir, [{"RINGTRACER_SOCKET", socket}])
    wait_for(socket, 600)
    {vm, 0} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{launcher}"])
    vm = String.trim(vm)
    ends_with_test(launcher, vm)
    {socket, {port, launcher}, vm}
  end

  # A test that fails half-way leaves no server running: woken and stopped.
  defp ends_with_test(launcher, vm) do
    on_exit(fn ->
      System.cmd("kill", ["-CONT", vm], stderr_to_stdout: true)
      System.cmd("kill", ["-TERM", "#{launcher}", vm], stderr_to_stdout: true)
    end)
  end

  defp elapsed_ms(t0), do: System.monotonic_time(:millisecond) - t0

  # A slow render through the server at `socket` only, once it has started
  # tracing, and the server's VM `vm` stopped then: {port, pid, when stopped}.
  defp stopped_mid_job(ctx, socket, vm, out, env \\ []) do
    env = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"} | env]
    args = ~w(render mine.nff -o #{out} --width 256 --speeds 400 --progress bar)
    {port, pid} = open(args, ctx.scenes, env)
    until(port, "atoms")
    {_, 0} = System.cmd("kill", ["-STOP", vm])
    {port, pid, System.monotonic_time(:millisecond)}
  end

  test "a stopped server: the render goes to a VM of its own within seconds, and never runs twice",
       ctx do
    {socket, server, vm} = own_server(ctx, "stopped")
    {_, 0} = System.cmd("kill", ["-STOP", vm])

    try do
      env = [{"RINGTRACER_SOCKET", socket}]
      args = ~w(render mine.nff --width 32 --atoms 4)
      t0 = System.monotonic_time(:millisecond)
      {0, out} = run(open(args ++ ~w(-o fell.png), ctx.scenes, env))
      assert out =~ "did not answer within 2 s"
      assert out =~ "wrote #{Path.join(ctx.scenes, "fell.png")}"
      refute out =~ "the server's, over all its renders"
      # two seconds for the server, then a VM's boot and a small render
      assert elapsed_ms(t0) < 30_000

      # told to use only the server, it fails as soon as the server misses its deadline
      t0 = System.monotonic_time(:millisecond)

      {1, out} =
        run(open(args ++ ~w(-o only.png), ctx.scenes, [{"RINGTRACER_SERVER", "only"} | env]))

      assert elapsed_ms(t0) < 10_000
      assert out =~ "did not answer within 2 s"

      # woken up, the server finds both requests unconfirmed: it renders neither
      File.rm!(Path.join(ctx.scenes, "fell.png"))
      {_, 0} = System.cmd("kill", ["-CONT", vm])

      {0, _} =
        run(open(args ++ ~w(-o woken.png), ctx.scenes, [{"RINGTRACER_SERVER", "only"} | env]))

      Process.sleep(1_000)
      refute File.exists?(Path.join(ctx.scenes, "fell.png"))
      refute File.exists?(Path.join(ctx.scenes, "only.png"))
    after
      System.cmd("kill", ["-CONT", vm])
      stop(server)
    end
  end

  for {signal, status} <- [{"INT", 130}, {"TERM", 143}] do
    test "SIG#{signal} ends a render within a second when its server stopped mid-job", ctx do
      {socket, server, vm} = own_server(ctx, "wedged#{unquote(signal)}")

      try do
        {port, pid, t0} = stopped_mid_job(ctx, socket, vm, "wedged.png")
        {_, 0} = System.cmd("kill", ["-#{unquote(signal)}", "#{pid}"])
        {status, out} = collect(port)
        took = elapsed_ms(t0)
        assert status == unquote(status), out
        assert out =~ "the server did not confirm"
        # 800 ms for the server, and the launcher's and the test's own latency
        assert took < 1_500, "#{took} ms"
      after
        System.cmd("kill", ["-CONT", vm])
        stop(server)
      end

      # the woken server cancelled the job of the client that went
      Process.sleep(3_000)
      refute File.exists?(Path.join(ctx.scenes, "wedged.png"))
    end
  end

  # The client allows 30 s of silence; RINGTRACER_SILENCE_WAIT makes it 5 here.
  test "a server stopped mid-job: its client gives up after the silence allowed", ctx do
    {socket, server, vm} = own_server(ctx, "silent")

    try do
      env = [{"RINGTRACER_SILENCE_WAIT", "5"}]
      {port, _pid, t0} = stopped_mid_job(ctx, socket, vm, "silent.png", env)
      {status, out} = collect(port)
      took = elapsed_ms(t0)
      assert status == 1, out
      assert out =~ "the server has sent nothing for 5 s"
      # up to 1 s between pings, then 5 s of silence allowed
      assert took in 3_000..20_000, "#{took} ms"
    after
      System.cmd("kill", ["-CONT", vm])
      stop(server)
    end
  end

  test "a job that fails takes no other with it, and each client prints its own reason", ctx do
    {socket, server, _vm} = own_server(ctx, "isolation")
    env = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"}]

    slow =
      open(
        ~w(render mine.nff -o kept.png --width 256 --speeds 400 --progress bar),
        ctx.scenes,
        env
      )

    until(elem(slow, 0), "atoms")
    {1, bad} = run(open(~w(render nowhere.nff -o bad.png), ctx.scenes, env))
    assert bad =~ "nowhere.nff"
    {0, good} = collect(elem(slow, 0))
    assert good =~ "wrote #{Path.join(ctx.scenes, "kept.png")}"
    refute good =~ "nowhere.nff"
    stop(server)
  end

  test "a server killed mid-job: each of its clients renders in a VM of its own", ctx do
    {socket, server, vm} = own_server(ctx, "killed")
    env = [{"RINGTRACER_SOCKET", socket}]
    args = ~w(render mine.nff --width 256 --speeds 400 --progress bar)

    clients =
      for name <- ~w(k1 k2), do: {name, open(args ++ ["-o", name <> ".png"], ctx.scenes, env)}

    for {_, {port, _}} <- clients, do: until(port, "atoms")
    {_, 0} = System.cmd("kill", ["-KILL", vm])

    for {name, {port, _}} <- clients do
      {status, out} = collect(port)
      assert status == 0, out
      assert out =~ "the server ended before this command did; rendering in a VM of its own"
      assert out =~ "wrote #{Path.join(ctx.scenes, name <> ".png")}"
    end

    stop(server)
  end

  # Stops a server of `own_server/2` and returns what it wrote (its log).
  defp stop_log({port, launcher}) do
    System.cmd("kill", ["-TERM", "#{launcher}"])
    {_, log} = collect(port)
    log
  end

  # The CPU time (user + system, seconds) OS process `pid` has used.
  defp cpu_seconds(pid) do
    [_, after_name] = String.split(File.read!("/proc/#{pid}/stat"), ")", parts: 2)
    fields = String.split(after_name)
    (String.to_integer(Enum.at(fields, 11)) + String.to_integer(Enum.at(fields, 12))) / 100
  end

  test "out of file descriptors, serve backs off, keeps logging and serves again", ctx do
    socket = Path.join([ctx.dir, "nofile", "serve.sock"])
    # 64 descriptors: the VM needs about 20, each waiting client takes one
    port =
      Port.open({:spawn_executable, "/bin/sh"}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: ["-c", "ulimit -n 64 && exec \"$0\" serve", @launcher],
        cd: ctx.dir,
        env: [{~c"RINGTRACER_SOCKET", String.to_charlist(socket)}]
      ])

    {:os_pid, launcher} = Port.info(port, :os_pid)
    wait_for(socket, 600)
    {vm, 0} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{launcher}"])
    vm = String.trim(vm)
    ends_with_test(launcher, vm)

    # clients that connect and say nothing, more than the server has descriptors for
    hogs =
      for _ <- 1..120,
          {:ok, s} <- [:gen_tcp.connect({:local, socket}, 0, [:local, active: false], 1_000)],
          do: s

    assert length(hogs) > 44
    Process.sleep(500)
    cpu0 = cpu_seconds(vm)
    Process.sleep(3_000)
    # a busy loop on accept would take most of a core for these 3 s
    assert cpu_seconds(vm) - cpu0 < 1.0
    Enum.each(hogs, &:gen_tcp.close/1)
    # the closed ones still in its queue are taken and dropped at once; its
    # pause between tries is at most 1 s
    log = until(port, "accepting commands again")
    Process.sleep(2_000)

    env = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"}]
    {0, out} = run(open(~w(render mine.nff -o nofile.png --width 16), ctx.scenes, env))
    assert out =~ "the server's, over all its renders"

    log = log <> stop_log({port, launcher})
    # one line for the run of failures, and the logger still works after it
    assert length(String.split(log, "cannot accept a command: too many open files")) in 2..4,
           log

    assert log =~ "accepting commands again"
    refute log =~ "removed"
  end

  test "--preview through the server: the page's address goes to the client, not the server's log",
       ctx do
    {socket, server, _vm} = own_server(ctx, "preview")
    env = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"}]
    {0, out} = run(open(~w(render mine.nff -o pv.png --width 16 --preview), ctx.scenes, env))
    assert [_, token] = Regex.run(~r{preview: http://127\.0\.0\.1:\d+/([^/\s]+)/}, out)
    log = stop_log(server)
    refute log =~ token
    refute log =~ "preview:"
  end

  test "~ in a served render's paths is the client's home, not the server's", ctx do
    home = Path.join(ctx.dir, "home")
    File.mkdir_p!(home)
    env = [{"RINGTRACER_SOCKET", ctx.socket}, {"RINGTRACER_SERVER", "only"}, {"HOME", home}]
    {0, out} = run(open(~w(render mine.nff --width 16 --out=~/tilde.png), ctx.scenes, env))
    assert out =~ "wrote #{Path.join(home, "tilde.png")}"
    assert File.exists?(Path.join(home, "tilde.png"))
  end

  test "a built checkout runs for a user without cargo on PATH", ctx do
    env = [{"HOME", ctx.dir}, {"PATH", "/usr/local/bin:/usr/bin:/bin"}]
    {0, out} = run(open(~w(render mine.nff -o nocargo.png --width 16), ctx.scenes, env))
    refute out =~ "cargo not found"
    assert out =~ "wrote"
  end

  test "the socket's folder must be this user's alone", ctx do
    open_dir = Path.join(ctx.dir, "open")
    File.mkdir_p!(open_dir)
    File.chmod!(open_dir, 0o755)
    assert {:error, message} = Server.check_dir(open_dir)
    assert message =~ "can be entered by others (chmod 700"

    {status, out} =
      run(open(["serve"], ctx.dir, [{"RINGTRACER_SOCKET", Path.join(open_dir, "s.sock")}]))

    assert status == 1
    assert out =~ "can be entered by others"

    # A second server on a live socket is refused.
    {status, out} = run(open(["serve"], ctx.dir, [{"RINGTRACER_SOCKET", ctx.socket}]))
    assert status == 1
    assert out =~ "a server is already running"
  end
end
