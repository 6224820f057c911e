defmodule RingTracer.Cluster.BuildDistributedTest do
  @moduledoc """
  A node of another build is refused wherever nodes meet before work: a
  render on it, a job's ring growing onto it, a farm worker's join, a
  submit to its farm. Each error names both builds, and nothing crashes
  mid-job. The peer pretends another build: its identity, read from
  `:persistent_term`, is replaced.
  """
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 120_000

  import ExUnit.CaptureLog

  alias RingTracer.Cluster.Build
  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait
  alias RingTracer.TestScenes

  @scene "whitted.toml"
  @w 64
  @h 48

  setup_all do
    Peers.ensure_distributed()
    {peer, n} = Peers.start("otherbuild")
    on_exit(fn -> Peers.stop(peer) end)
    # The peer's own build is computed (by RingTracer.Cluster, once it has
    # started) before the tests put another one in its place.
    _ = Peers.call(peer, n, :sys, :get_state, [RingTracer.Cluster])
    {:ok, peer: peer, other: n}
  end

  setup %{peer: peer, other: n} do
    ours = Build.identity()
    other = %{ours | version: "0.0.1", code: :erlang.md5("another build")}
    pretend(peer, n, other)
    on_exit(fn -> pretend(peer, n, ours) end)

    me = self()
    id = "build-distributed-#{System.unique_integer([:positive])}"

    :ok =
      RingTracer.Telemetry.attach(
        id,
        [:ring_tracer, :atom, :stop],
        fn _, _, md, _ -> send(me, {:atom, md.node}) end,
        nil
      )

    on_exit(fn -> RingTracer.Telemetry.detach(id) end)
    {:ok, ours: Build.short(ours), theirs: Build.short(other)}
  end

  # The peer's build, as identity/0 reads it there.
  defp pretend(peer, n, build),
    do: Peers.call(peer, n, :persistent_term, :put, [Build.key(), build])

  defp both?(message, n, ours, theirs),
    do: message =~ "node #{n} runs build #{theirs}, node #{node()} runs build #{ours}"

  test "a render on a node of another build is refused before any atom, naming both builds",
       %{other: n, ours: ours, theirs: theirs} do
    assert {:error, %RingTracer.Error{reason: :build_mismatch, message: message}} =
             RingTracer.render(TestScenes.path(@scene), nodes: [node(), n], width: @w, height: @h)

    assert both?(message, n, ours, theirs)
    refute_received {:atom, _}
  end

  test "ringtracer render --nodes to a node of another build fails, naming both builds",
       %{other: n, ours: ours, theirs: theirs} do
    dir = Path.join(System.tmp_dir!(), "rt_build_cli_#{System.unique_integer([:positive])}")
    File.mkdir_p!(dir)
    on_exit(fn -> File.rm_rf!(dir) end)
    out = Path.join(dir, "out.png")
    args = [TestScenes.path(@scene), "-o", out, "--nodes", "#{n}", "--width", "48"]

    err =
      ExUnit.CaptureIO.capture_io(:stderr, fn ->
        assert RingTracer.CLI.Render.run(args ++ ["--progress", "none"]) != 0
      end)

    assert both?(err, n, ours, theirs)
    refute File.exists?(out)
    refute_received {:atom, _}
  end

  test "a running job does not grow onto a node of another build, and ends whole",
       %{other: n, ours: ours, theirs: theirs} do
    opts = [kernel: {RingTracer.Test.FaultyKernel, delay: 8}, width: @w, height: @h, atoms: 32]
    {:ok, job} = RingTracer.render_async(TestScenes.path(@scene), opts ++ [children: 2])
    assert_receive {:atom, _}, 10_000

    # through the public call (its pre-flight check) ...
    assert {:error, %RingTracer.Error{reason: :build_mismatch, message: message}} =
             RingTracer.grow(job, n, 2)

    assert both?(message, n, ours, theirs)

    # ... and the job's parent itself, asked directly (no pre-flight check)
    ref = :erlang.monitor(:process, job.pid, [{:alias, :demonitor}])
    send(job.pid, {:job_request, {:grow, ref, n, 2}})
    assert_receive {^ref, {:error, {:node_unavailable, message}}}, 15_000
    Process.demonitor(ref, [:flush])
    assert both?(message, n, ours, theirs)

    assert {:ok, result} = await(job.id)
    assert result.failures == []
    refute Map.has_key?(result.nodes, n)
    assert result.pixels == TestScenes.reference(@scene, @w, @h)
  end

  test "a worker of another build does not join a farm; it logs why and backs off",
       %{peer: peer, other: n, ours: ours, theirs: theirs} do
    farm_head()
    on_exit(fn -> Peers.call(peer, n, Farm, :leave, []) end)
    # The worker's log of the refusal is its state here (its logger is the peer's).
    Peers.call(peer, n, Logger, :put_module_level, [Farm.Member, :none])
    on_exit(fn -> Peers.call(peer, n, Logger, :delete_module_level, [Farm.Member]) end)

    {:ok, _} = Peers.call(peer, n, Farm, :join, [node(), [slots: 1]])
    assert Wait.eventually(fn -> refused(peer, n) != nil end, 1_000)

    # The worker's own check: "node HEAD runs build OURS, node WORKER runs build THEIRS".
    assert refused(peer, n) =~ "node #{node()} runs build #{ours}, node #{n} runs build #{theirs}"
    assert {:ok, []} = Farm.workers(node())
    refute Peers.call(peer, n, Farm.Member, :joined?, [])

    # Of the same build again, it joins by itself at its next try.
    pretend(peer, n, Build.identity())
    assert Wait.eventually(fn -> Peers.call(peer, n, Farm.Member, :joined?, []) end, 1_000)
    assert {:ok, [_]} = Farm.workers(node())
  end

  test "a head refuses the join of a worker of another build, naming both",
       %{peer: peer, other: n, ours: ours, theirs: theirs} do
    farm_head()
    # A member of the peer's build, as one that skips its own check (an older one) joins.
    member = Peers.call(peer, n, :erlang, :whereis, [:init])
    about = %{tags: [], slots: 1, speed: 1, build: Peers.call(peer, n, Build, :identity, [])}

    log =
      capture_log(fn ->
        assert {:error, %RingTracer.Error{reason: :build_mismatch, message: message}} =
                 GenServer.call(RingTracer.Names.farm_head(), {:join, n, about, member})

        assert both?(message, n, ours, theirs)
      end)

    assert log =~ "farm: refused worker #{n}"
    assert {:ok, []} = Farm.workers(node())

    # One too old to tell its build is refused too.
    capture_log(fn ->
      assert {:error, %RingTracer.Error{message: message}} =
               GenServer.call(
                 RingTracer.Names.farm_head(),
                 {:join, n, Map.delete(about, :build), member}
               )

      assert message =~ "node #{n} runs an unknown build, node #{node()} runs build #{ours}"
    end)
  end

  test "a submit to a head of another build is refused, naming both builds",
       %{peer: peer, other: n, ours: ours, theirs: theirs} do
    dir = Path.join(System.tmp_dir!(), "rt_build_submit_#{System.unique_integer([:positive])}")
    {:ok, _} = Peers.call(peer, n, Farm, :start_head, [[dir: dir]])

    on_exit(fn ->
      Peers.call(peer, n, Farm, :stop_head, [])
      File.rm_rf!(dir)
    end)

    assert {:error, %RingTracer.Error{reason: :build_mismatch, message: message}} =
             Farm.submit(n, TestScenes.path(@scene), width: @w, height: @h)

    assert both?(message, n, ours, theirs)
    assert {:ok, []} = Peers.call(peer, n, Farm, :jobs, [n])
  end

  # A head on this node, stopped and its folder removed after the test.
  defp farm_head do
    dir = Path.join(System.tmp_dir!(), "rt_build_farm_#{System.unique_integer([:positive])}")
    {:ok, _} = Farm.start_head(dir: dir)

    on_exit(fn ->
      Farm.stop_head()
      File.rm_rf!(dir)
    end)
  end

  # The worker's refusal, as its membership keeps it (nil: none yet).
  defp refused(peer, n) do
    member = Peers.call(peer, n, Process, :whereis, [RingTracer.Names.farm_member()])
    member && Peers.call(peer, n, :sys, :get_state, [member]).refused
  end

  defp await(id) do
    receive do
      {RingTracer, ^id, {:progress, _, _}} -> await(id)
      {RingTracer, ^id, final} -> final
    after
      60_000 -> flunk("the job did not end")
    end
  end
end
