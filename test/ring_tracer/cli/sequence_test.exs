defmodule RingTracer.CLI.SequenceTest do
  use ExUnit.Case, async: true

  alias RingTracer.CLI.{Frames, Sequence}

  @moduletag :tmp_dir

  # A job's messages, without a job: what `RingTracer.render_sequence/2`
  # sends, to a handle whose process tells the test the frames acknowledged
  # and waits to be cancelled.
  defp handle do
    me = self()
    pid = spawn(fn -> job(me) end)
    %{id: make_ref(), pid: pid}
  end

  defp job(test) do
    receive do
      {:ack, n} ->
        send(test, {:acked, n})
        job(test)

      {:cancel, _from, _ref} ->
        send(test, :cancelled)
    end
  end

  defp job, do: %{render_opts: [children: 1, atoms: 2], mode: :quiet, opts: []}

  defp frame(n, grey) do
    %RingTracer.Frame{
      number: n,
      width: 2,
      height: 1,
      pixels: :binary.copy(<<grey::float-32-native>>, 2 * 3),
      released_us: 100 * n,
      completed_us: 100 * n + 50,
      atoms: 2,
      traced: %{0 => 2},
      rays: %{RingTracer.Rays.zero() | eye: 2}
    }
  end

  defp result do
    %RingTracer.Result{
      width: 2,
      height: 1,
      pixels: nil,
      elapsed_us: 1,
      children: [],
      rays: RingTracer.Rays.zero(),
      settings: nil
    }
  end

  defp collect(handle, dir, numbers) do
    {:ok, plan} = Frames.plan([], Path.join(dir, "f_##.png"), 4, "four.toml")
    {:ok, held} = RingTracer.Output.open_dir(dir)
    Sequence.collect(handle, make_ref(), job(), plan, numbers, held)
  end

  defp same_as_alone(dir, n, frame) do
    alone = Path.join(dir, "alone_#{n}.png")
    :ok = RingTracer.Image.write(alone, frame.width, frame.height, frame.pixels)
    File.read!(Path.join(dir, "f_0#{n}.png")) == File.read!(alone)
  end

  test "each frame is written to its numbered file as it arrives, in any order", %{tmp_dir: dir} do
    h = handle()
    frames = Map.new([2, 4, 3], &{&1, frame(&1, &1 / 4)})
    for n <- [4, 2, 3], do: send(self(), {RingTracer, h.id, {:frame, n, frames[n]}})
    result = result()
    send(self(), {RingTracer, h.id, {:ok, result}})

    assert {:ok, ^result, summaries} = collect(h, dir, [2, 3, 4])

    assert Enum.map(summaries, &{&1.number, &1.elapsed_us, &1.atoms}) == [
             {4, 50, 2},
             {2, 50, 2},
             {3, 50, 2}
           ]

    for n <- [2, 3, 4], do: assert(same_as_alone(dir, n, frames[n]))
    # each acknowledged once written, so that it leaves the job's window
    for n <- [4, 2, 3], do: assert_receive({:acked, ^n})
    refute File.exists?(Path.join(dir, "f_01.png"))
  end

  test "a frame that cannot be written cancels the job; those written before stay", %{
    tmp_dir: dir
  } do
    h = handle()
    File.mkdir!(Path.join(dir, "f_02.png"))
    send(self(), {RingTracer, h.id, {:frame, 1, frame(1, 0.5)}})
    send(self(), {RingTracer, h.id, {:frame, 2, frame(2, 0.5)}})
    send(self(), {RingTracer, h.id, {:frame, 3, frame(3, 0.5)}})

    assert {:error, message} = collect(h, dir, [1, 2, 3])
    assert message =~ "f_02.png"
    assert message =~ "the frame written is whole and kept (--continue renders the rest)"
    assert_receive :cancelled
    assert_received {:acked, 1}
    refute_received {:acked, 2}
    assert same_as_alone(dir, 1, frame(1, 0.5))
    # the job's messages after the cancel are not left in the mailbox
    refute_received {RingTracer, _, _}
  end

  test "a job that ends short of a frame, or sends one not asked for, is an error", %{
    tmp_dir: dir
  } do
    h = handle()
    send(self(), {RingTracer, h.id, {:frame, 1, frame(1, 0.5)}})
    send(self(), {RingTracer, h.id, {:ok, result()}})
    assert {:error, message} = collect(h, dir, [1, 2])
    assert message =~ "the job ended without frames 2"

    h = handle()
    send(self(), {RingTracer, h.id, {:frame, 4, frame(4, 0.5)}})
    assert {:error, message} = collect(h, dir, [1, 2])
    assert message =~ "frame 4, which was not asked for"
    assert_receive :cancelled
    refute File.exists?(Path.join(dir, "f_04.png"))
  end

  test "an interrupt cancels the job and says how many frames were written", %{tmp_dir: dir} do
    h = handle()
    send(self(), {RingTracer, h.id, {:frame, 3, frame(3, 0.5)}})
    send(self(), {RingTracer.CLI.Signals, :sigint})
    send(self(), {RingTracer, h.id, {:frame, 1, frame(1, 0.5)}})

    assert {:interrupted, :sigint, 1} = collect(h, dir, [1, 2, 3])
    assert_receive :cancelled
    assert File.ls!(dir) == ["f_03.png"]
  end
end
