defmodule RingTracer.Farm.RestartTest do
  use ExUnit.Case, async: true

  @moduletag :distributed
  @moduletag timeout: 240_000

  alias RingTracer.Cluster.Distribution
  alias RingTracer.Farm
  alias RingTracer.LocalCluster, as: Peers
  alias RingTracer.Test.Wait
  alias RingTracer.TestScenes

  @w 160
  @h 120

  setup do
    Peers.ensure_distributed()
    dir = Path.join(System.tmp_dir!(), "rt_farm_restart_#{System.unique_integer([:positive])}")
    name = String.to_atom(Distribution.unique_name("head"))
    workers = for w <- ["rw1", "rw2"], do: Peers.start(w)
    on_exit(fn -> File.rm_rf!(dir) end)
    {:ok, dir: dir, name: name, workers: workers}
  end

  defp start_head(name, dir) do
    {peer, head} = Peers.start("head", name: name)
    {:ok, _} = Peers.call(peer, head, Farm, :start_head, [[dir: dir]])
    {peer, head}
  end

  defp kill9(peer, head) do
    os_pid = Peers.call(peer, head, System, :pid, [])
    ref = Process.monitor(peer)
    {_, 0} = System.cmd("kill", ["-9", os_pid])
    assert_receive {:DOWN, ^ref, _, _, _}, 10_000
  end

  defp done_at(peer, head, id) do
    Peers.call(peer, head, :mnesia, :dirty_match_object, [{:ring_tracer_farm_frame, {id, :_}, :_}])
    |> Map.new(fn {_, {_, n}, at} -> {n, at} end)
  end

  defp messages do
    {:messages, messages} = Process.info(self(), :messages)
    messages
  end

  test "after kill -9 of the head every job resumes, workers join again by themselves, " <>
         "no frame done is rendered again and every frame is whole",
       %{dir: dir, name: name, workers: workers} do
    {peer, head} = start_head(name, dir)
    for {p, n} <- workers, do: {:ok, _} = Peers.call(p, n, Farm, :join, [head, [slots: 1]])
    assert Wait.eventually(fn -> match?({:ok, [_, _]}, Farm.workers(head)) end, 1000)

    # The twentieth atom traced on the first worker is held until the head
    # is killed, so that its frame cannot be done before the kill. A frame
    # has eight atoms (whole: the ring does not split them by default), so
    # it is the third frame's or a later one's, and the frames before it are
    # done: nothing holds them (the held atom's grandchild holds one more,
    # the next in its child's queue, no earlier). The held
    # atom's child dies with the head; the job, started again, goes on
    # counting and does not hold another.
    [{_, rw1} | _] = workers
    ref = make_ref()
    kernel = {RingTracer.Test.FaultyKernel, block: {rw1, 20, self(), ref}}
    scene = TestScenes.path("whitted_orbit.toml")

    {:ok, id} =
      Farm.submit(head, scene, width: @w, height: @h, atoms: 4, user: "ann", kernel: kernel)

    {:ok, queued} = Farm.submit(head, scene, width: 32, height: 24, frames: 1..2, user: "bob")

    # The workers are stopped (SIGSTOP) once the held atom's frame and those
    # before it are reached, until the head is dead, so that no frame is
    # stored between the read of those done and the kill.
    assert_receive {:blocked, ^ref, _}, 60_000
    os_pids = for {p, n} <- workers, do: Peers.call(p, n, System, :pid, [])
    on_exit(fn -> System.cmd("kill", ["-CONT" | os_pids], stderr_to_stdout: true) end)
    assert Wait.eventually(fn -> elem(Farm.status(head, id), 1).done != [] end, 3000)
    {_, 0} = System.cmd("kill", ["-STOP" | os_pids])
    before = done_at(peer, head, id)

    # A wait that has subscribed and is handed the frames done so far: the
    # head is killed as it hands over the first, and the wait goes on once
    # the head is back, every frame handed over once.
    me = self()

    waiting =
      Task.async(fn ->
        Farm.wait(head, id,
          on_frame: fn n, bytes ->
            send(me, {:frame, n, bytes})

            if Process.put(:held, true) == nil do
              send(me, {:first, self()})
              receive do: (:go_on -> :ok)
            end

            :ok
          end
        )
      end)

    assert_receive {:first, waiter}, 30_000
    kill9(peer, head)
    send(waiter, :go_on)
    {_, 0} = System.cmd("kill", ["-CONT" | os_pids])
    assert map_size(before) in 1..47

    {peer, ^head} = start_head(name, dir)
    on_exit(fn -> Peers.stop(peer) end)
    # The workers find the head again without being told.
    assert Wait.eventually(fn -> match?({:ok, [_, _]}, Farm.workers(head)) end, 1000)

    {:ok, info} = Task.await(waiting, 180_000)
    assert {info.state, info.done} == {:done, Enum.to_list(1..48)}
    # The frames done before the kill kept their rows: none was traced again.
    after_ = done_at(peer, head, id)
    for {n, at} <- before, do: assert(after_[n] == at)

    handed = for {:frame, n, _} <- messages(), do: n
    assert Enum.sort(handed) == Enum.to_list(1..48)

    for n <- [1, 24, 48] do
      assert_received {:frame, ^n, png}
      reference = TestScenes.reference("whitted_orbit.toml", @w, @h, frame: n)
      assert {:ok, png} == RingTracer.Image.png(@w, @h, reference)
    end

    assert {:ok, %{state: :done, done: [1, 2]}} = Farm.wait(head, queued)
    assert {:ok, %{stored_twice: 0}} = Farm.overview(head)
  end
end
