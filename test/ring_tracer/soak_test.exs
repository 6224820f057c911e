defmodule RingTracer.SoakTest do
  use ExUnit.Case, async: false

  @moduletag :slow
  @moduletag timeout: 300_000

  alias RingTracer.TestScenes

  defp snapshot do
    for pid <- Process.list(), do: :erlang.garbage_collect(pid)

    %{
      processes: length(Process.list()),
      ets: length(:ets.all()),
      memory: :erlang.memory(:total),
      scenes: RingTracer.Native.scene_live_count(),
      pipe_entries: :ets.info(RingTracer.Names.pipe_table(), :size)
    }
  end

  test "200 consecutive jobs leave processes, ETS tables, memory and scenes flat" do
    run = fn i ->
      strategy = Enum.at(RingTracer.Strategies.names(), rem(i, 4))

      {:ok, _} =
        RingTracer.render(TestScenes.path("balls_s1.nff"),
          children: 3,
          atoms: 4,
          width: 24,
          height: 16,
          strategy: strategy,
          # One slower child, so that queued atoms are taken back from pipes.
          speeds: [1, 3, 1]
        )
    end

    # Warm up (scene cache, code loading), then measure. Tests that kill
    # children leave their grandchildren's pipe entries to the minutely
    # sweep (`RingTracer.Job.Pipe`): sweep them now, so that what is left
    # at the end is this test's own.
    Enum.each(1..10, run)
    RingTracer.Job.Pipe.sweep()
    before = snapshot()
    Enum.each(1..200, run)
    after_ = snapshot()

    IO.puts("soak: before #{inspect(before)}, after #{inspect(after_)}")
    assert after_.processes == before.processes
    assert after_.ets == before.ets
    assert after_.scenes == before.scenes
    assert after_.pipe_entries == 0
    assert after_.memory - before.memory < 2_000_000
  end

  test "concurrent jobs in one VM do not interfere" do
    scenes = ["balls_s1.nff", "tetra_s1.nff", "whitted.toml"]
    references = Map.new(scenes, &{&1, TestScenes.reference(&1, 40, 30)})

    results =
      for i <- 1..12 do
        scene = Enum.at(scenes, rem(i, 3))

        Task.async(fn ->
          {scene,
           RingTracer.render(TestScenes.path(scene),
             children: 1 + rem(i, 4),
             atoms: 5,
             width: 40,
             height: 30
           )}
        end)
      end
      |> Task.await_many(60_000)

    for {scene, {:ok, result}} <- results, do: assert(result.pixels == references[scene])
    assert length(results) == 12
  end
end
