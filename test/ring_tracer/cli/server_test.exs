defmodule RingTracer.CLI.ServerTest do
  # `ringtracer serve` and the launcher's client, as users run them: real OS
  # processes, from another folder, interrupted with real signals.
  use ExUnit.Case, async: false

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
