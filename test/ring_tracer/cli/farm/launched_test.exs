defmodule RingTracer.CLI.Farm.LaunchedTest do
  # A farm as users run it: `bin/ringtracer farm`, `worker --join` and
  # `submit`, each a real OS process of the launcher (TLS with the user's
  # own certificates, the default cookie file), from another folder.
  use ExUnit.Case, async: true

  import RingTracer.Test.PortOutput, only: [collect: 1, until: 2]

  @moduletag :distributed
  @moduletag timeout: 240_000
  @launcher Path.expand("bin/ringtracer")

  setup do
    dir =
      Path.join(
        System.tmp_dir!(),
        "rt_farm_cli_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}"
      )

    File.mkdir_p!(dir)
    File.cp!("priv/scenes/balls_s2.nff", Path.join(dir, "mine.nff"))
    on_exit(fn -> File.rm_rf!(dir) end)
    # The first run builds the application (MIX_ENV=prod) if it is stale.
    {_, 0} = System.cmd(@launcher, ["farm", "--help"], stderr_to_stdout: true)
    {:ok, dir: dir}
  end

  defp start(dir, args) do
    port =
      Port.open({:spawn_executable, @launcher}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: args,
        cd: dir,
        env: [{~c"XDG_STATE_HOME", String.to_charlist(Path.join(dir, "state"))}]
      ])

    {:os_pid, launcher} = Port.info(port, :os_pid)
    # A test that fails half-way leaves no node running.
    on_exit(fn -> System.cmd("kill", ["-TERM", "#{launcher}"], stderr_to_stdout: true) end)
    {port, launcher}
  end

  test "a head, a worker joined, a submission that writes a PNG, and Ctrl-C ends them", ctx do
    head = "fhead_#{System.unique_integer([:positive])}"
    {head_port, head_pid} = start(ctx.dir, ["farm", "--sname", head])
    out = until(head_port, "dashboard:")
    assert out =~ "RingTracer farm head #{head}@localhost ready"
    # The dashboard, on loopback by default, behind a token.
    assert [_, url] = Regex.run(~r{dashboard:  (http://127\.0\.0\.1:\d+/[\w-]+/)\n}, out)
    assert out =~ "join it:    ringtracer worker --join #{head}@localhost"

    # The default folder, under the state folder, closed to others.
    state = Path.join([ctx.dir, "state", "ringtracer", "farm"])
    assert File.stat!(Path.join(state, "#{head}@localhost")).mode |> Bitwise.band(0o077) == 0
    assert File.stat!(state).mode |> Bitwise.band(0o777) == 0o700

    {worker_port, worker_pid} = start(ctx.dir, ["worker", "--join", head, "--slots", "2"])
    until(worker_port, "farm: joined #{head}@localhost")

    {submit, _} = start(ctx.dir, ~w(submit mine.nff -o mine.png --width 64 --farm #{head}))
    {status, text} = collect(submit)
    assert status == 0, text
    assert text =~ ~r/job \d+ queued on #{head}@localhost: mine.nff, frame 1/
    png = File.read!(Path.join(ctx.dir, "mine.png"))
    assert <<0x89, "PNG", _::binary>> = png

    {jobs, _} = start(ctx.dir, ["jobs", "--farm", head])
    {0, text} = collect(jobs)
    assert text =~ ~r/^\s+1  done\s+1\/1 .* mine.nff$/m
    assert text =~ "workers (1):"

    {:ok, _} = Application.ensure_all_started(:inets)

    {:ok, {{_, 200, _}, _, json}} =
      :httpc.request(:get, {String.to_charlist(url <> "state.json"), []}, [timeout: 5_000], [])

    state = :jiffy.decode(json, [:return_maps])
    assert [%{"state" => "done", "scene" => "mine.nff"}] = state["jobs"]
    assert [%{"node" => "worker_" <> _}] = state["workers"]

    for {pid, port} <- [{worker_pid, worker_port}, {head_pid, head_port}] do
      {_, 0} = System.cmd("kill", ["-INT", "#{pid}"])
      assert {130, _} = collect(port)
    end
  end
end
