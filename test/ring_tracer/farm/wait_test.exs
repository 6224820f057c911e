defmodule RingTracer.Farm.WaitTest do
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 120_000

  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.TestScenes

  @tag :tmp_dir
  test "wait returns farm_unreachable as soon as the head dies, not at its timeout",
       %{tmp_dir: dir} do
    Peers.ensure_distributed()
    {peer, head} = Peers.start("waithead")
    on_exit(fn -> Peers.stop(peer) end)
    {:ok, _} = Peers.call(peer, head, Farm, :start_head, [[dir: Path.join(dir, "head")]])

    # No worker: the job stays queued, and wait would block until its timeout.
    {:ok, id} = Farm.submit(head, TestScenes.path("balls_s2.nff"), width: 8, height: 6)
    waiting = Task.async(fn -> Farm.wait(head, id, timeout: 100_000) end)
    {:ok, %{state: :queued}} = Farm.status(head, id)

    os_pid = Peers.call(peer, head, System, :pid, [])
    {_, 0} = System.cmd("kill", ["-9", os_pid])

    assert {:error, %RingTracer.Error{reason: :farm_unreachable}} = Task.await(waiting, 15_000)
  end
end
