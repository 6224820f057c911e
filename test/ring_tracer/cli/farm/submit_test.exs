defmodule RingTracer.CLI.Farm.SubmitTest do
  # The farm's commands as the launcher runs them (`execute/1,2` of
  # RingTracer.CLI.Farm.Submit and .Jobs), in this node: a head here, two
  # peers as workers.
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  @moduletag :distributed
  @moduletag timeout: 240_000

  alias RingTracer.CLI.Farm.{Jobs, Submit}
  alias RingTracer.CLI.Render
  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait
  alias RingTracer.TestScenes

  doctest RingTracer.CLI.Farm.Client
  doctest RingTracer.CLI.Farm.Show

  setup_all do
    Peers.ensure_distributed()
    peers = for name <- ["cfw1", "cfw2"], do: Peers.start(name)
    dir = Path.join(System.tmp_dir!(), "rt_cli_farm_#{System.unique_integer([:positive])}")
    {:ok, _} = Farm.start_head(dir: dir)
    for {p, n} <- peers, do: {:ok, _} = Peers.call(p, n, Farm, :join, [node(), [slots: 2]])
    assert Wait.eventually(fn -> match?({:ok, [_, _]}, Farm.workers(node())) end, 1000)

    on_exit(fn ->
      Farm.stop_head()
      Enum.each(peers, fn {p, _} -> Peers.stop(p) end)
      File.rm_rf!(dir)
    end)

    {:ok, head: Atom.to_string(node())}
  end

  @tag :tmp_dir
  test "a still is submitted, waited for and written as render writes it", ctx do
    out = Path.join(ctx.tmp_dir, "farm.png")
    scene = TestScenes.path("balls_s2.nff")

    {result, text} =
      with_io(fn -> Submit.execute([scene, "-o", out, "--width", "64", "--farm", ctx.head]) end)

    assert result == :ok, inspect({result, text})
    assert text =~ ~r/job \d+ queued on #{ctx.head}: balls_s2.nff, frame 1/
    assert text =~ "wrote #{out} (frame 1)"

    assert File.read!(out) == rendered(ctx, scene, "render.png", ["--width", "64"])
  end

  @tag :tmp_dir
  test "a sequence's frames reach the submitter's folder, each as render writes it", ctx do
    scene = TestScenes.path("whitted_orbit.toml")
    out = Path.join(ctx.tmp_dir, "f_###.png")
    args = ["--width", "48", "--frames", "2-4"]

    {:ok, _} = with_io(fn -> Submit.execute([scene, "-o", out, "--farm", ctx.head] ++ args) end)

    for n <- 2..4 do
      file = "f_00#{n}.png"

      assert File.read!(Path.join(ctx.tmp_dir, file)) ==
               rendered(ctx, scene, "r_###.png", args, "r_00#{n}.png")
    end
  end

  @tag :tmp_dir
  test "--no-wait, then wait, status, jobs and fetch --continue", ctx do
    scene = TestScenes.path("whitted_orbit.toml")
    out = Path.join(ctx.tmp_dir, "o_#.png")

    {:ok, text} =
      with_io(fn ->
        Submit.execute(
          [scene, "-o", out, "--width", "32", "--frames", "1-3", "--no-wait"] ++
            ["--farm", ctx.head, "--user", "ann", "-q"]
        )
      end)

    id = text |> String.trim() |> String.to_integer()
    refute File.exists?(Path.join(ctx.tmp_dir, "o_1.png"))

    assert {:ok, text} = with_io(fn -> Jobs.execute("wait", ["#{id}", "--farm", ctx.head]) end)
    assert text =~ "job #{id} done: 3 of 3 frames"

    {:ok, text} = with_io(fn -> Jobs.execute("status", ["#{id}", "--farm", ctx.head]) end)
    assert text =~ "job #{id}: done"
    assert text =~ "user:      ann"
    assert text =~ "frames:    3 done of 3 (1-3)"
    assert text =~ "(32x24)"

    {:ok, text} = with_io(fn -> Jobs.execute("jobs", ["--farm", ctx.head]) end)
    assert text =~ ~r/^\s+#{id}  done\s+3\/3 .* ann\s+whitted_orbit.toml$/m
    assert text =~ "workers (2):"

    # Frame 2 is there already: --continue leaves it as it is.
    File.write!(Path.join(ctx.tmp_dir, "o_2.png"), "mine")

    {:ok, text} =
      with_io(fn -> Jobs.execute("fetch", ["#{id}", "--continue", "--farm", ctx.head]) end)

    assert text =~ "2 frames written, 1 there already"
    assert File.read!(Path.join(ctx.tmp_dir, "o_2.png")) == "mine"

    assert File.read!(Path.join(ctx.tmp_dir, "o_3.png")) ==
             rendered(ctx, scene, "r_#.png", ["--width", "32", "--frames", "1-3"], "r_3.png")

    # Another pattern, and its format checked against the job's.
    other = Path.join(ctx.tmp_dir, "again_##.png")

    {:ok, _} =
      with_io(fn -> Jobs.execute("fetch", ["#{id}", "-o", other, "-q", "--farm", ctx.head]) end)

    assert File.exists?(Path.join(ctx.tmp_dir, "again_01.png"))

    assert {{:error, 2, message}, _} =
             with_io(fn ->
               Jobs.execute("fetch", ["#{id}", "-o", "x_#.exr", "--farm", ctx.head])
             end)

    assert message =~ "frames are PNG files"
  end

  @tag :tmp_dir
  test "cancel stops a job; an interrupted submission leaves its job running", ctx do
    scene = TestScenes.path("whitted_orbit.toml")
    out = Path.join(ctx.tmp_dir, "slow_##.png")
    slow = ["--width", "64", "--speeds", "1000", "--atoms", "4", "--farm", ctx.head]

    # Ctrl-C once the job is queued: the command stops waiting, with 130.
    {:ok, before} = Farm.jobs(node())
    me = self()

    spawn_link(fn ->
      queued = fn -> length(elem(Farm.jobs(node()), 1)) > length(before) end
      assert Wait.eventually(queued, 3000)
      send(me, {RingTracer.CLI.Signals, :sigint})
    end)

    {{:error, 130, message}, text} = with_io(fn -> Submit.execute([scene, "-o", out] ++ slow) end)
    [_, id] = Regex.run(~r/job (\d+) queued/, text)
    assert message =~ "stopped waiting; 0 frames written, whole; job #{id} goes on"
    assert {:ok, %{state: state}} = Farm.status(node(), String.to_integer(id))
    assert state in [:queued, :running]

    {:ok, text} = with_io(fn -> Jobs.execute("cancel", [id, "--farm", ctx.head]) end)
    assert text =~ "job #{id} cancelled"
    assert {:ok, %{state: :cancelled}} = Farm.status(node(), String.to_integer(id))

    assert {{:error, 1, message}, _} =
             with_io(fn -> Jobs.execute("cancel", [id, "--farm", ctx.head]) end)

    assert message =~ "has ended (cancelled)"

    assert {{:error, 1, message}, _} =
             with_io(fn -> Jobs.execute("wait", [id, "--farm", ctx.head]) end)

    assert message == "job #{id} cancelled"
  end

  @tag :tmp_dir
  test "bad input: a clear message, and render's exit statuses", ctx do
    scene = TestScenes.path("balls_s2.nff")
    out = Path.join(ctx.tmp_dir, "x.png")
    farm = ["--farm", ctx.head]

    for {args, status, text} <- [
          {[Path.join(ctx.tmp_dir, "missing.nff"), "-o", out] ++ farm, 1, "missing.nff"},
          {[scene, "-o", out, "--widht", "9"] ++ farm, 2, "did you mean --width?"},
          {[scene, "-o", out, "--children", "4"] ++ farm, 2, "--children is not for a farm job"},
          {[scene, "-o", out, "--stats", "s.json"] ++ farm, 2, "statistics stay on the head"},
          {[scene, "-o", out, "--depth", "0"] ++ farm, 2, "--depth takes an integer from 1"},
          {[scene, "-o", out, "--tags", "a b"] ++ farm, 2, "--tags must be a list of tags"},
          {[scene, "-o", out], 2, "--farm HEAD is required"},
          {[scene] ++ farm, 2, "--out FILE is required"},
          {[scene, "-o", out, "--cookie", "c"] ++ farm, 2, "--cookie-file"},
          {[scene, "-o", Path.join(ctx.tmp_dir, "f.png"), "--frames", "1-2"] ++ farm, 2,
           "balls_s2.nff has 1 frame"},
          {["-o", out] ++ farm, 2, "give a scene file"}
        ] do
      assert {{:error, ^status, message}, _} = with_io(fn -> Submit.execute(args) end),
             inspect(args)

      assert message =~ text
    end

    for {command, args, status, text} <- [
          {"status", ["abc"], 2, "(a positive integer), got: abc"},
          {"status", ["999999"], 1, "no job 999999 on this farm"},
          {"cancel", [], 2, "give a job's id"},
          {"jobs", ["7"], 2, "takes no argument"},
          {"fetch", ["999999"], 1, "no job 999999"}
        ] do
      assert {{:error, ^status, message}, _} =
               with_io(fn -> Jobs.execute(command, args ++ farm) end)

      assert message =~ text
    end

    refute File.exists?(out)
  end

  test "--help on every farm command, with its usage and examples; exit 0" do
    for command <- ~w(farm submit jobs status wait cancel fetch worker) do
      {status, text} = with_io(fn -> RingTracer.CLI.run([command, "--help"]) end)
      assert status == 0, command
      assert text =~ "Usage: ringtracer #{command}"
      assert text =~ ~r/Examples?:/
    end

    {0, text} = with_io(fn -> RingTracer.CLI.run(["--help"]) end)
    assert text =~ "submit SCENE --out FILE --farm HEAD"
  end

  @tag :tmp_dir
  test "an interrupt before the job is queued queues nothing", ctx do
    {:ok, before} = Farm.jobs(node())
    send(self(), {RingTracer.CLI.Signals, :sigterm})
    args = [TestScenes.path("balls_s2.nff"), "-o", Path.join(ctx.tmp_dir, "i.png")]

    assert {{:error, 143, "terminated; nothing queued"}, _} =
             with_io(fn -> Submit.execute(args ++ ["--farm", ctx.head]) end)

    assert Farm.jobs(node()) == {:ok, before}
  end

  test "a head that cannot be reached is an error within the call's deadline" do
    t0 = System.monotonic_time(:millisecond)

    assert {{:error, 1, message}, _} =
             with_io(fn ->
               Submit.execute(
                 [TestScenes.path("balls_s2.nff"), "-o", "/tmp/x.png"] ++
                   ["--farm", "nohead_#{System.unique_integer([:positive])}"]
               )
             end)

    assert message =~ "cannot reach the farm head nohead_"
    assert {{:error, 1, _}, _} = with_io(fn -> Jobs.execute("jobs", ["--farm", "nohead"]) end)
    assert System.monotonic_time(:millisecond) - t0 < 15_000
  end

  # What `ringtracer render` writes for the same scene and options (frame
  # file `name` of it).
  defp rendered(ctx, scene, out, args, name \\ nil) do
    dir = Path.join(ctx.tmp_dir, "render")
    File.mkdir_p!(dir)
    {:ok, _} = with_io(fn -> Render.execute([scene, "-o", Path.join(dir, out), "-q"] ++ args) end)
    File.read!(Path.join(dir, name || out))
  end
end
