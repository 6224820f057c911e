defmodule RingTracer.CLI.ServerFaultsTest do
  # `ringtracer serve` under faults: a failing job beside others, a killed
  # server, no file descriptors left, a preview's token (`RingTracer.CLI.ServerTest`).
  use RingTracer.Test.ServeCase, async: true

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

  test "out of file descriptors, serve backs off, keeps logging and serves again", ctx do
    socket = Path.join([ctx.dir, "nofile", "serve.sock"])
    # 64 descriptors: the VM needs about 20, each waiting client takes one
    port =
      Port.open({:spawn_executable, "/bin/sh"}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: ["-c", "ulimit -n 64 && exec \"$0\" serve", launcher()],
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
end
