defmodule RingTracer.CLI.ServerTest do
  # `ringtracer serve` and the launcher's client, as users run them: real OS
  # processes, from another folder, interrupted with real signals. The
  # servers that stop answering, and other faults, are in
  # `server_wedged_test.exs` and `server_faults_test.exs`.
  use RingTracer.Test.ServeCase, async: true

  alias RingTracer.CLI.Server

  doctest RingTracer.CLI.Server.Session

  setup_all ctx do
    {:ok, Serve.shared_server(ctx.dir)}
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
    args = ~w(render mine.nff --width 128 --speeds 200 --progress bar)
    # How long the job takes when nothing stops it.
    t0 = System.monotonic_time(:millisecond)
    {0, _} = run(served(ctx, args ++ ~w(-o whole.png)))
    whole_ms = System.monotonic_time(:millisecond) - t0

    {port, pid} = served(ctx, args ++ ~w(-o killed.png))
    # The launcher's client (found before its job starts, so that only the
    # kill stands between the job's start and the client's end).
    client = child_of(pid)
    until(port, "atoms")
    # Killed as a second Ctrl-C would.
    {_, 0} = System.cmd("kill", ["-KILL", client])
    {status, _out} = collect(port)
    assert status != 0

    # A job that went on would have written its image by now.
    Process.sleep(whole_ms + 2_000)
    refute File.exists?(Path.join(ctx.scenes, "killed.png"))
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

  # The OS pid of the thin client `pid` (the launcher) runs, once it runs it
  # (10 s at most).
  # Up to 60 s: a loaded machine once took over 10 s to start the launcher's client.
  defp child_of(pid, tries \\ 1200) do
    case System.cmd("pgrep", ["-P", "#{pid}", "-x", "ringtracer-clie"]) do
      {out, 0} -> String.trim(out)
      _ when tries > 0 -> Process.sleep(50) && child_of(pid, tries - 1)
      _ -> flunk("#{pid} started no client")
    end
  end
end
