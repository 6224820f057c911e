defmodule RingTracer.CLI.ServerWedgedTest do
  # `ringtracer serve` stopped (SIGSTOP) before or during a render: what its
  # clients do, and what it does once woken (`RingTracer.CLI.ServerTest`).
  use RingTracer.Test.ServeCase, async: true

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
        {port, pid, _} = stopped_mid_job(ctx, socket, vm, "wedged.png")
        # From the signal's delivery (`kill` has returned; its own start-up,
        # slow on a loaded machine, is not the client's).
        {_, 0} = System.cmd("kill", ["-#{unquote(signal)}", "#{pid}"])
        t0 = System.monotonic_time(:millisecond)
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
end
