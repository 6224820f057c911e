defmodule RingTracer.CLITest do
  # The launcher as users run it: a real OS process, from another folder,
  # through a symlink on the PATH, interrupted with real signals.
  use ExUnit.Case, async: true

  import RingTracer.Test.PortOutput, only: [collect: 1, until: 2]

  @moduletag :distributed
  @moduletag timeout: 180_000
  @launcher Path.expand("bin/ringtracer")

  setup_all do
    dir =
      Path.join(System.tmp_dir!(), "rt_cli_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")

    bin = Path.join(dir, "bin")
    scenes = Path.join(dir, "scenes")
    File.mkdir_p!(bin)
    File.mkdir_p!(scenes)
    File.ln_s!(@launcher, Path.join(bin, "ringtracer"))
    File.cp!("priv/scenes/balls_s2.nff", Path.join(scenes, "mine.nff"))
    on_exit(fn -> File.rm_rf!(dir) end)
    # The first run builds the application (MIX_ENV=prod) if it is stale.
    {_, 0} = System.cmd(@launcher, ["render", "--help"], stderr_to_stdout: true)
    {:ok, dir: dir, bin: bin, scenes: scenes}
  end

  defp start(ctx, args) do
    port =
      Port.open({:spawn_executable, Path.join(ctx.bin, "ringtracer")}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: args,
        cd: ctx.scenes,
        env: [
          {~c"PATH", String.to_charlist("#{ctx.bin}:#{System.get_env("PATH")}")},
          # A VM of its own, even if a `ringtracer serve` of this checkout runs
          # (test/ring_tracer/cli/server_test.exs runs these through one).
          {~c"RINGTRACER_SERVER", ~c"off"}
        ]
      ])

    {:os_pid, pid} = Port.info(port, :os_pid)
    {port, pid}
  end

  defp run(ctx, args) do
    {port, _} = start(ctx, args)
    collect(port)
  end

  test "renders from any folder through a symlink, paths against the caller's folder", ctx do
    {status, out} = run(ctx, ["render", "mine.nff", "--out", "mine.png", "--width", "64"])
    assert status == 0, out
    assert File.exists?(Path.join(ctx.scenes, "mine.png"))
    # --width alone keeps the scene's aspect ratio (balls is square).
    assert out =~ "mine.png (64x64)"
    assert out =~ ~r/rays: \d+ .*Mrays\/s/
    assert out =~ "peak memory"
  end

  test "--help on every command, with examples; exit 0", ctx do
    for args <- [
          ["--help"],
          ["render", "--help"],
          ["render", "-h"],
          ["worker", "--help"],
          ["cookie", "-h"]
        ] do
      {status, out} = run(ctx, args)
      assert status == 0, "#{inspect(args)}: #{out}"
      assert out =~ "Usage: ringtracer"
    end

    {_, out} = run(ctx, ["render", "--help"])
    assert out =~ "Examples:"
    assert out =~ "Exit status"
  end

  test "usage errors name the option or value and exit 2; a failed render exits 1", ctx do
    {2, out} = run(ctx, ["render", "mine.nff", "-o", "x.png", "--childs", "4"])
    assert out =~ "unknown option --childs (did you mean --children?)"

    {2, out} = run(ctx, ["render", "mine.nff", "-o", "x.png", "--children", "abc"])
    assert out =~ "--children takes an integer from 1 to 16384, got: abc"

    {2, out} = run(ctx, ["render", "mine.nff", "-o", "x.png", "--depth", "0"])
    assert out =~ "--depth takes an integer from 1 to 64, got: 0"

    {2, out} = run(ctx, ["rendr"])
    assert out =~ "did you mean render?"

    {1, out} = run(ctx, ["render", "missing.nff", "-o", "x.png"])
    assert out =~ "missing.nff"
  end

  for {signal, status} <- [{"INT", 130}, {"TERM", 143}] do
    test "SIG#{signal} cancels the render: status #{status}, every process gone, no file", ctx do
      # A slowed render with its progress bar forced on, so that we know it runs.
      {port, pid} =
        start(ctx, ~w(render mine.nff -o slow.png --width 256 --speeds 400 --progress bar))

      until(port, "atoms")
      {_, 0} = System.cmd("kill", ["-#{unquote(signal)}", "#{pid}"])
      {status, out} = collect(port)

      assert status == unquote(status), out
      assert out =~ ~r/interrupted|terminated/
      refute File.exists?(Path.join(ctx.scenes, "slow.png"))
      assert Enum.filter(File.ls!(ctx.scenes), &String.contains?(&1, "slow")) == []
      # No VM of it is left: the launcher's children are gone with it.
      {ps, _} = System.cmd("ps", ["-o", "pid=", "--ppid", "#{pid}"])
      assert String.trim(ps) == ""
    end
  end

  for {signal, status} <- [{"INT", 130}, {"TERM", 143}] do
    test "SIG#{signal} while the VM boots still cancels: status #{status}, no file", ctx do
      # Slowed down and large enough to take seconds (at 64 pixels wide it
      # took half a second, and a loaded machine once let the whole render
      # end before `kill` ran), so that however late the signal comes
      # through, the render has not ended by then.
      {port, pid} = start(ctx, ~w(render mine.nff -o early.png --width 256 --speeds 400))
      # The launcher's VM has just been started: the signal comes while it
      # boots, or while the scene parses (the launcher holds it until the VM
      # takes it).
      assert RingTracer.Test.Wait.eventually(fn -> vm_started?(pid) end, 3_000)
      {_, 0} = System.cmd("kill", ["-#{unquote(signal)}", "#{pid}"])
      {status, out} = collect(port)

      assert status == unquote(status), out
      assert out =~ ~r/(interrupted|terminated); nothing written/, out
      refute File.exists?(Path.join(ctx.scenes, "early.png"))
    end
  end

  # Whether the launcher `pid` has started its VM (erl has exec'd the
  # emulator; it has not necessarily booted).
  defp vm_started?(pid) do
    {ps, _} = System.cmd("ps", ["-o", "comm=", "--ppid", "#{pid}"])
    "beam.smp" in String.split(ps)
  end
end
