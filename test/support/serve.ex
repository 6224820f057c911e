defmodule RingTracer.Test.Serve do
  @moduledoc """
  `ringtracer serve` and the launcher's client as users run them, for the
  tests of `RingTracer.CLI.Server` (three modules, so that ExUnit runs them
  side by side): a private folder with a scene, servers, clients, signals.
  """
  import ExUnit.Assertions, only: [flunk: 1]
  import RingTracer.Test.PortOutput, only: [collect: 1, until: 2]

  @doc "The launcher, by its absolute path."
  def launcher, do: Path.expand("bin/ringtracer")

  @doc """
  A private folder (removed when the module's tests end) with `scenes/mine.nff`:
  `%{dir: _, scenes: _}`. For `setup_all`.
  """
  def folder do
    dir =
      Path.join(System.tmp_dir!(), "rt_serve_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")

    scenes = Path.join(dir, "scenes")
    File.mkdir_p!(scenes)
    File.cp!("priv/scenes/balls_s2.nff", Path.join(scenes, "mine.nff"))
    ExUnit.Callbacks.on_exit(fn -> File.rm_rf!(dir) end)
    %{dir: dir, scenes: scenes}
  end

  @doc """
  A server on `dir/run/serve.sock` that lives as long as the module's tests
  (its port belongs to a process of its own): `%{socket: _, server: _}`. For `setup_all`.
  """
  def shared_server(dir) do
    socket = Path.join([dir, "run", "serve.sock"])
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

    ExUnit.Callbacks.on_exit(fn ->
      send(holder, {:stop, self(), server})
      receive do: ({:stopped, _} -> :ok), after: (15_000 -> :ok)
    end)

    %{socket: socket, server: server}
  end

  # `umask`: the launcher runs under that umask (through sh), else the test VM's.
  def open(args, cd, env, umask \\ nil) do
    {exe, args} =
      if umask,
        do: {"/bin/sh", ["-c", "umask #{umask} && exec \"$0\" \"$@\"", launcher() | args]},
        else: {launcher(), args}

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

  def wait_for(_path, 0), do: flunk("ringtracer serve did not start")

  def wait_for(path, n) do
    unless File.exists?(path) do
      Process.sleep(50)
      wait_for(path, n - 1)
    end
  end

  def stop({port, pid}) do
    System.cmd("kill", ["-TERM", "#{pid}"])

    receive do
      {^port, {:exit_status, _}} -> :ok
    after
      10_000 -> System.cmd("kill", ["-KILL", "#{pid}"])
    end
  end

  def served(ctx, args),
    do: open(args, ctx.scenes, [{"RINGTRACER_SOCKET", ctx.socket}, {"RINGTRACER_SERVER", "only"}])

  def auto(ctx, args), do: open(args, ctx.scenes, [{"RINGTRACER_SOCKET", ctx.socket}])
  def own_vm(ctx, args), do: open(args, ctx.scenes, [{"RINGTRACER_SERVER", "off"}])

  def run(opened) do
    {port, _} = opened
    collect(port)
  end

  # A second server of the tests' own, on a socket of its own, whose VM the
  # test may stop (SIGSTOP): its OS pid is the launcher's child.
  def own_server(ctx, name) do
    socket = Path.join([ctx.dir, name, "serve.sock"])
    {port, launcher} = open(["serve"], ctx.dir, [{"RINGTRACER_SOCKET", socket}])
    wait_for(socket, 600)
    {vm, 0} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{launcher}"])
    vm = String.trim(vm)
    ends_with_test(launcher, vm)
    {socket, {port, launcher}, vm}
  end

  # A test that fails half-way leaves no server running: woken and stopped.
  def ends_with_test(launcher, vm) do
    ExUnit.Callbacks.on_exit(fn ->
      System.cmd("kill", ["-CONT", vm], stderr_to_stdout: true)
      System.cmd("kill", ["-TERM", "#{launcher}", vm], stderr_to_stdout: true)
    end)
  end

  def elapsed_ms(t0), do: System.monotonic_time(:millisecond) - t0

  # A slow render through the server at `socket` only, once it has started
  # tracing, and the server's VM `vm` stopped then: {port, pid, when stopped}.
  def stopped_mid_job(ctx, socket, vm, out, env \\ []) do
    env = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"} | env]
    args = ~w(render mine.nff -o #{out} --width 256 --speeds 400 --progress bar)
    {port, pid} = open(args, ctx.scenes, env)
    until(port, "atoms")
    {_, 0} = System.cmd("kill", ["-STOP", vm])
    {port, pid, System.monotonic_time(:millisecond)}
  end

  # Stops a server of `own_server/2` and returns what it wrote (its log).
  def stop_log({port, launcher}) do
    System.cmd("kill", ["-TERM", "#{launcher}"])
    {_, log} = collect(port)
    log
  end

  # The CPU time (user + system, seconds) OS process `pid` has used.
  def cpu_seconds(pid) do
    [_, after_name] = String.split(File.read!("/proc/#{pid}/stat"), ")", parts: 2)
    fields = String.split(after_name)
    (String.to_integer(Enum.at(fields, 11)) + String.to_integer(Enum.at(fields, 12))) / 100
  end
end
