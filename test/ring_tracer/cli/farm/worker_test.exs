defmodule RingTracer.CLI.Farm.WorkerTest do
  # `ringtracer worker --join HEAD` (RingTracer.CLI.Worker.start/1, as the
  # launcher calls it) in a peer: it joins, and joins again by itself after
  # `kill -9` of the head and a restart under the same name.
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 180_000

  alias RingTracer.CLI.Worker
  alias RingTracer.Cluster.Distribution
  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait

  setup do
    Peers.ensure_distributed()
    dir = Path.join(System.tmp_dir!(), "rt_cli_farm_w_#{System.unique_integer([:positive])}")
    name = String.to_atom(Distribution.unique_name("head"))
    on_exit(fn -> File.rm_rf!(dir) end)
    {:ok, dir: dir, name: name}
  end

  defp start_head(name, dir) do
    {peer, head} = Peers.start("head", name: name)
    {:ok, _} = Peers.call(peer, head, Farm, :start_head, [[dir: dir]])
    {peer, head}
  end

  @tag :tmp_dir
  test "a worker started with --join joins, and again after the head's kill -9 and restart; " <>
         "a fetch --wait goes on through the restart",
       %{dir: dir, name: name, tmp_dir: tmp_dir} do
    {peer, head} = start_head(name, dir)
    {wp, wn} = Peers.start("cw")
    on_exit(fn -> Peers.stop(wp) end)

    assert {:ok, ^wn, line} =
             Peers.call(wp, wn, Worker, :start, [
               ["--join", "#{head}", "--slots", "1", "--tags", "big-mem,x", "--speed", "2"]
             ])

    assert line =~ "RingTracer worker #{wn} ready"
    assert line =~ "joining the farm #{head}"

    joined = fn -> match?({:ok, [%{node: ^wn}]}, Farm.workers(head)) end
    assert Wait.eventually(joined, 1000)
    {:ok, [info]} = Farm.workers(head)
    assert {info.slots, info.tags, info.speed} == {1, ["big-mem", "x"], 2.0}

    # A sequence under way, fetched as it goes by `ringtracer fetch --wait`.
    scene = RingTracer.TestScenes.path("whitted_orbit.toml")
    out = Path.join(tmp_dir, "f_##.png")
    {:ok, id} = Farm.submit(head, scene, width: 160, height: 120, atoms: 4, out: out)
    args = ["#{id}", "--wait", "-q", "--farm", "#{head}"]

    fetch =
      Task.async(fn ->
        ExUnit.CaptureIO.with_io(fn -> RingTracer.CLI.Farm.Jobs.execute("fetch", args) end)
      end)

    # Killed part way, once the fetch has subscribed (it has written a frame).
    assert Wait.eventually(fn -> Path.wildcard(Path.join(tmp_dir, "f_*.png")) != [] end, 3000)
    assert {:ok, %{state: :running}} = Farm.status(head, id)

    os_pid = Peers.call(peer, head, System, :pid, [])
    ref = Process.monitor(peer)
    {_, 0} = System.cmd("kill", ["-9", os_pid])
    assert_receive {:DOWN, ^ref, _, _, _}, 10_000

    {peer, ^head} = start_head(name, dir)
    on_exit(fn -> Peers.stop(peer) end)
    # Nobody tells the worker: it finds the head again by itself.
    assert Wait.eventually(joined, 1000)

    # The fetch waited for the head, subscribed again and got every frame.
    assert {:ok, _} = Task.await(fetch, 180_000)
    assert length(Path.wildcard(Path.join(tmp_dir, "f_*.png"))) == 48
    reference = RingTracer.TestScenes.reference("whitted_orbit.toml", 160, 120, frame: 48)

    assert {:ok, File.read!(Path.join(tmp_dir, "f_48.png"))} ==
             RingTracer.Image.png(160, 120, reference)
  end

  test "a farm worker's options are checked before the node starts" do
    assert {:error, message} = Worker.start(["--slots", "2"])
    assert message =~ "give --join HEAD with them"

    assert {:error, message} = Worker.start(["--join", "a b"])
    assert message =~ "--join takes the head's node name"

    assert {:error, "invalid option(s): --slots"} = Worker.start(["--join", "h", "--slots", "x"])
  end
end
