defmodule RingTracer.Job.GrowTest do
  @moduledoc """
  An elastic ring on one node (`RingTracer.grow/4`, `RingTracer.shrink/3`):
  children that join a running still or sequence trace atoms, whatever the
  strategy, and the images are byte-identical to an ungrown render.
  """
  use ExUnit.Case, async: false

  alias RingTracer.{Error, TestScenes}

  import RingTracer.TestScenes, only: [children: 0]

  @moduletag timeout: 120_000
  doctest RingTracer.Job.Elastic

  @still "balls_s1.nff"
  @sequence "whitted_orbit.toml"
  @w 40
  @h 30

  # Each atom takes at least 6 ms more than its tracing: the job is still
  # running when the children join, at its start.
  defp slow(opts),
    do: [kernel: {RingTracer.Test.FaultyKernel, delay: 6}, width: @w, height: @h] ++ opts

  # The job's messages until its end; a sequence's frames are acknowledged
  # as they come (`ack: true`).
  defp await(%{id: id} = job, frames \\ %{}) do
    receive do
      {RingTracer, ^id, {:frame, n, frame}} ->
        RingTracer.ack_frame(job, n)
        await(job, Map.put(frames, n, frame))

      {RingTracer, ^id, {:progress, _, _}} ->
        await(job, frames)

      {RingTracer, ^id, final} ->
        {final, frames}
    after
      60_000 -> flunk("the job did not end")
    end
  end

  defp joined_traced(result, n) do
    result.children |> Enum.filter(&(&1.index >= n)) |> Enum.map(& &1.traced)
  end

  setup_all do
    {:ok,
     still: TestScenes.reference(@still, @w, @h),
     frames: Map.new([1, 2, 3], &{&1, TestScenes.reference(@sequence, @w, @h, frame: &1)})}
  end

  for strategy <- RingTracer.Strategies.names() do
    test "#{strategy}: children that join a still trace atoms; the image is the same",
         %{still: reference} do
      strategy = unquote(strategy)

      {:ok, job} =
        RingTracer.render_async(
          TestScenes.path(@still),
          slow(children: 2, atoms: 12, strategy: strategy)
        )

      assert {:ok, [2, 3]} = RingTracer.grow(job, node(), 2)
      assert {{:ok, result}, _} = await(job)

      assert result.pixels == reference
      assert length(result.children) == 4
      assert result.failures == []
      traced = joined_traced(result, 2)
      # Static has nothing for a child that joins a still: it finishes.
      if strategy == :static,
        do: assert(traced == [0, 0]),
        else: assert(Enum.sum(traced) > 0)

      assert Enum.sum(Enum.map(result.children, & &1.traced)) >= 24
      assert result.nodes[node()].children == 4
    end

    test "#{strategy}: children that join a sequence trace later frames; every frame is the same",
         %{frames: references} do
      strategy = unquote(strategy)

      {:ok, job} =
        RingTracer.render_sequence(
          TestScenes.path(@sequence),
          slow(frames: 1..3, window: 1, ack: true, children: 2, atoms: 6, strategy: strategy)
        )

      # Frame 2 is released once frame 1 is acknowledged, after the join.
      assert {:ok, [2]} = RingTracer.grow(job, node(), 1)
      assert {{:ok, result}, frames} = await(job)

      assert Map.keys(frames) |> Enum.sort() == [1, 2, 3]
      for {n, frame} <- frames, do: assert(frame.pixels == references[n], "frame #{n}")
      # Frames after the first are cut over the three children: the new
      # one's strips of frames 2 and 3 are 4 atoms each, which static's
      # children keep (the ring's and steal's may share some).
      assert [traced] = joined_traced(result, 2)
      if strategy == :static, do: assert(traced == 2 * 4), else: assert(traced > 0)
    end
  end

  test "a grow telemetry event names the node and the children that joined" do
    me = self()

    :ok =
      RingTracer.Telemetry.attach(
        "grow-test",
        [:ring_tracer, :job, :grown],
        fn _, m, md, _ -> send(me, {:grown, m, md}) end,
        nil
      )

    on_exit(fn -> RingTracer.Telemetry.detach("grow-test") end)
    {:ok, job} = RingTracer.render_async(TestScenes.path(@still), slow(children: 1, atoms: 8))
    assert {:ok, [1, 2, 3]} = RingTracer.grow(job, node(), 3)
    assert_receive {:grown, %{children: 3}, %{node: node, joined: [1, 2, 3], size: 4}}, 5_000
    assert node == node()
    assert {{:ok, _}, _} = await(job)
  end

  test "after the job's end, :job_ended; bad counts, nodes and options are named" do
    {:ok, job} =
      RingTracer.render_async(TestScenes.path(@still), width: 8, height: 8, children: 1)

    assert {{:ok, _}, _} = await(job)

    assert {:error, %Error{reason: :job_ended}} = RingTracer.grow(job, node(), 1)
    assert {:error, %Error{reason: :job_ended}} = RingTracer.shrink(job, node())

    assert {:error, %Error{reason: :invalid_option, message: "count must be" <> _}} =
             RingTracer.grow(job, node(), 0)

    assert {:error, %Error{reason: :invalid_option}} = RingTracer.grow(job, "w1", 1)

    assert {:error, %Error{reason: :invalid_option}} =
             RingTracer.grow(job, node(), 1, timeout: -1)

    assert {:error, %Error{reason: :node_unavailable}} = RingTracer.grow(job, :nobody@nowhere, 1)
  end

  test "a job may not grow beyond its maximum of children" do
    {:ok, job} = RingTracer.render_async(TestScenes.path(@still), slow(children: 2, atoms: 4))

    assert {:error, %Error{reason: :invalid_option, message: msg}} =
             RingTracer.grow(job, node(), 16_383)

    assert msg =~ "at most 16384 children"
    assert {{:ok, result}, _} = await(job)
    assert length(result.children) == 2
  end

  test "shrink: a node without children of the job leaves it as it is; the last children stay" do
    {:ok, job} = RingTracer.render_async(TestScenes.path(@still), slow(children: 2, atoms: 8))
    assert {:ok, []} = RingTracer.shrink(job, :other@nowhere)

    assert {:error, %Error{reason: :invalid_option, message: msg}} =
             RingTracer.shrink(job, node())

    assert msg =~ "none would stay"
    assert {{:ok, result}, _} = await(job)
    assert result.failures == []
    assert RingTracer.Test.Wait.eventually(fn -> children() == [] end)
  end
end
