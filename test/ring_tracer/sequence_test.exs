defmodule RingTracer.SequenceTest do
  @moduledoc """
  Sequences (`RingTracer.render_sequence/2`): one ring for many frames,
  each frame byte-identical to the same frame rendered alone.
  """
  use ExUnit.Case, async: false

  alias RingTracer.TestScenes

  import RingTracer.TestScenes, only: [children: 0]

  @moduletag timeout: 120_000
  doctest RingTracer.Sequence

  # Objects move (a bouncing sphere) and the camera orbits: 48 frames.
  @scene "whitted_orbit.toml"
  @w 24
  @h 18

  setup_all do
    refs = Map.new([1, 2, 7, 13, 24, 30, 47, 48], &{&1, reference(&1)})
    {:ok, refs: refs}
  end

  defp reference(n), do: TestScenes.reference(@scene, @w, @h, frame: n)

  # Every message of the sequence until its end: the frames by number (a
  # number twice fails), the progress seen, and the final reply.
  defp collect(id, frames \\ %{}, progress \\ []) do
    receive do
      {RingTracer, ^id, {:frame, n, frame}} ->
        refute Map.has_key?(frames, n), "frame #{n} came twice"
        collect(id, Map.put(frames, n, frame), progress)

      {RingTracer, ^id, {:progress, done, total}} ->
        collect(id, frames, [{done, total} | progress])

      {RingTracer, ^id, final} ->
        {frames, Enum.reverse(progress), final}
    after
      60_000 -> flunk("the sequence did not end")
    end
  end

  defp run(opts) do
    {:ok, job} = RingTracer.render_sequence(TestScenes.path(@scene), opts)
    collect(job.id)
  end

  @numbers [1, 7, 13, 30, 47, 48]
  @cases for strategy <- RingTracer.Strategies.names(),
             layout <- RingTracer.Layout.orders(),
             split <- if(strategy == :ring, do: [false, true], else: [false]),
             do: {strategy, layout, split}

  for {strategy, layout, split} <- @cases do
    test "every frame equals the frame rendered alone: #{strategy}, #{layout}, split #{split}",
         %{refs: refs} do
      {frames, _progress, {:ok, result}} =
        run(
          frames: @numbers,
          window: 2,
          width: @w,
          height: @h,
          children: 3,
          atoms: 3,
          strategy:
            if(unquote(strategy) == :ring,
              do: {:ring, split: unquote(split)},
              else: unquote(strategy)
            ),
          layout: unquote(layout),
          speeds: [1, 3]
        )

      assert Map.keys(frames) |> Enum.sort() == @numbers

      for n <- @numbers do
        assert frames[n].pixels == refs[n], "frame #{n} differs from the frame alone"
        assert {frames[n].width, frames[n].height, frames[n].atoms} == {@w, @h, 9}
      end

      assert result.pixels == nil
      assert Enum.map(result.frames, & &1.number) |> Enum.sort() == @numbers
      assert Enum.all?(result.frames, &(&1.pixels == nil))
      assert Enum.sum(Enum.map(result.children, & &1.traced)) >= 9 * length(@numbers)
      assert result.duplicates == 0
      assert children() == []
    end
  end

  test "at most the window of frames is in flight", %{refs: refs} do
    window = 2

    {frames, progress, {:ok, _}} =
      run(frames: 1..8, window: window, width: @w, height: @h, children: 2, atoms: 2)

    by_index = frames |> Map.values() |> Enum.sort_by(& &1.number) |> List.to_tuple()

    # Frame i + window is released only once frames 0..i are all complete.
    for i <- 0..(8 - window - 1) do
      done = for j <- 0..i, do: elem(by_index, j).completed_us
      assert elem(by_index, i + window).released_us >= Enum.max(done)
    end

    assert frames[1].pixels == refs[1] and frames[7].pixels == refs[7]
    assert List.last(progress) == {8 * 4, 8 * 4}
  end

  test "with ack, frames leave the window only once acknowledged", %{refs: refs} do
    {:ok, job} =
      RingTracer.render_sequence(TestScenes.path(@scene),
        frames: 1..5,
        window: 2,
        ack: true,
        width: @w,
        height: @h,
        children: 2
      )

    id = job.id
    first = for _ <- 1..2, do: receive_frame(id)
    assert Enum.sort(Enum.map(first, & &1.number)) == [1, 2]
    # Nothing more is released until the caller acknowledges a frame.
    refute_receive {RingTracer, ^id, {:frame, _, _}}, 300
    :ok = RingTracer.ack_frame(job, 2)
    refute_receive {RingTracer, ^id, {:frame, _, _}}, 300
    :ok = RingTracer.ack_frame(job, 1)
    # Frames 3 and 4 are released together; they complete in about, not
    # exactly, their order (render_sequence/2's contract).
    next = Map.new(for(_ <- 1..2, do: receive_frame(id)), &{&1.number, &1})
    assert Enum.sort(Map.keys(next)) == [3, 4]
    assert next[3].pixels == TestScenes.reference(@scene, @w, @h, frame: 3)

    # Frame 5 waits for 3, the oldest in the window: acknowledging 4 alone
    # releases nothing.
    refute_receive {RingTracer, ^id, {:frame, _, _}}, 300
    :ok = RingTracer.ack_frame(job, 4)
    refute_receive {RingTracer, ^id, {:frame, _, _}}, 300
    :ok = RingTracer.ack_frame(job, 3)
    assert receive_frame(id).number == 5
    :ok = RingTracer.ack_frame(job, 5)
    assert_receive {RingTracer, ^id, {:ok, result}}, 30_000
    assert length(result.frames) == 5 and hd(first).pixels == refs[hd(first).number]
  end

  defp receive_frame(id) do
    receive do
      {RingTracer, ^id, {:frame, _, frame}} -> frame
    after
      30_000 -> flunk("no frame")
    end
  end

  test "a subset keeps the whole sequence's clock", %{refs: refs} do
    {frames, _, {:ok, _}} = run(frames: 47..48, width: @w, height: @h, children: 2)
    assert frames[47].pixels == refs[47] and frames[48].pixels == refs[48]
    assert frames[47].pixels != refs[1]
  end

  test "a child killed mid-sequence loses no frame and sends none twice", %{refs: refs} do
    numbers = [1, 2, 7, 13, 24, 30]

    {:ok, job} =
      RingTracer.render_sequence(TestScenes.path(@scene),
        frames: numbers,
        window: 2,
        width: @w,
        height: @h,
        children: 3,
        atoms: 4,
        speeds: [40]
      )

    id = job.id

    receive do
      {RingTracer, ^id, {:frame, _, _}} -> :ok
    after
      30_000 -> flunk("no first frame")
    end

    [victim | _] = children()
    Process.exit(victim, :kill)
    {frames, _, {:ok, result}} = collect(id)

    # The first frame was taken out of the mailbox above; the rest came once each.
    assert map_size(frames) == length(numbers) - 1
    for {n, frame} <- frames, do: assert(frame.pixels == refs[n], "frame #{n} differs")
    assert [%{reason: ":killed"}] = result.failures
    assert children() == []
  end

  test "stream_sequence/2 gives the frames, and halting it stops the job", %{refs: refs} do
    frames =
      RingTracer.stream_sequence(TestScenes.path(@scene),
        frames: [2, 24],
        width: @w,
        height: @h,
        children: 2
      )
      |> Enum.sort_by(& &1.number)

    assert Enum.map(frames, & &1.pixels) == [refs[2], refs[24]]

    [first] =
      RingTracer.stream_sequence(TestScenes.path(@scene),
        frames: 1..48,
        width: @w,
        height: @h,
        children: 2,
        speeds: [20]
      )
      |> Enum.take(1)

    assert %RingTracer.Frame{} = first
    assert RingTracer.Test.Wait.eventually(fn -> children() == [] end)
  end

  test "bad options are errors before any work" do
    path = TestScenes.path(@scene)

    for {opts, message} <- [
          {[frames: 0..2], "option :frames must name frames from 1 to 48"},
          {[frames: [3, 2]], "option :frames must be a range"},
          {[window: 0], "option :window must be an integer from 1 to 64"},
          {[frame: 2], "option :frame is not one of a sequence's"},
          {[aim: true], "option :aim is the ring's own"},
          {[strategy: {:ring, aim: true}], "the ring's :aim works within one image"},
          {[children: 0], "option :children must be a positive integer"}
        ] do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: got}} =
               RingTracer.render_sequence(path, opts)

      assert got =~ message
    end

    assert {:error, %RingTracer.Error{}} = RingTracer.render_sequence("no/such/scene.toml")
    assert children() == []
  end
end
