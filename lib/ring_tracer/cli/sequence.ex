defmodule RingTracer.CLI.Sequence do
  @moduledoc false
  # `ringtracer render` of a sequence of frames: one job
  # (`RingTracer.render_sequence/2`) traces them all; each frame is written
  # to its file (`RingTracer.CLI.Frames.path/2`) as soon as it arrives,
  # atomically, in the folder held open once, then acknowledged: a frame
  # leaves the job's window only once written, so a disk slower than the
  # ring holds the ring back rather than frames piling up in memory. A frame that cannot be
  # written, an interrupt or a failed job cancels the job; the frames
  # written before are whole and stay (`--continue` renders the rest).
  # Statistics, timeline: written once the job has ended, all or none.

  alias RingTracer.CLI.{Console, Frames, Progress, Report, Signals}

  @typedoc "What the command goes on with: as `RingTracer.CLI.Render`'s steps."
  @type outcome ::
          :ok
          | {:usage, String.t()}
          | {:error, String.t()}
          | {:interrupted, :sigint | :sigterm, non_neg_integer()}

  @doc """
  Renders `numbers` (the frames of `plan` left to render) of `scene` and
  writes them in `dir` (the frames' folder, from
  `RingTracer.Output.open_dir/1`), then the reports; prints the statistics
  unless quiet.
  """
  @spec run(RingTracer.Scene.t(), map(), Frames.t(), [pos_integer()], term(), non_neg_integer()) ::
          outcome()
  def run(scene, job, plan, numbers, dir, load_us) do
    opts =
      job.render_opts
      |> Keyword.drop([:frame, :region, :window])
      |> Keyword.merge(frames: numbers, ack: true)
      |> then(&if w = job.opts[:window], do: Keyword.put(&1, :window, w), else: &1)

    me = self()
    handler = {__MODULE__, make_ref()}

    :ok =
      RingTracer.Telemetry.attach(
        handler,
        [:ring_tracer, :atom, :stop],
        fn _e, m, md, _ -> send(me, {handler, md.job, m.rays, md.total}) end,
        nil
      )

    result =
      try do
        case RingTracer.render_sequence(scene, opts) do
          {:ok, handle} -> collect(handle, handler, job, plan, numbers, dir)
          {:error, error} -> refused(error)
        end
      after
        RingTracer.Telemetry.detach(handler)
      end

    with {:ok, result, frames} <- result,
         :ok <- not_interrupted(length(frames)),
         :ok <- write_reports(result, job, length(frames)) do
      if !job.opts[:quiet], do: IO.write(report(job, plan, result, frames, load_us))
      :ok
    end
  end

  @doc """
  Receives the job's messages until it ends: feeds the progress display,
  writes each frame as it arrives. `{:ok, result, frames}` (the frames'
  summaries, in the order they arrived) or what ended it.
  """
  @spec collect(map(), term(), map(), Frames.t(), [pos_integer()], term()) ::
          {:ok, RingTracer.Result.t(), [map()]} | outcome()
  def collect(handle, handler, job, plan, numbers, dir) do
    children = Keyword.get(job.render_opts, :children, :erlang.system_info(:schedulers_online))

    atoms =
      children * Keyword.get(job.render_opts, :atoms, RingTracer.Options.default(:atoms)) *
        length(numbers)

    progress = job.mode |> Progress.new(atoms, now()) |> Progress.frames(0, length(numbers))
    schedule(job.mode)

    state = %{
      handle: handle,
      handler: handler,
      progress: progress,
      plan: plan,
      left: MapSet.new(numbers),
      count: length(numbers),
      dir: dir,
      mode: [mode: Console.new_file_mode()],
      frames: []
    }

    await(state)
  end

  defp await(%{handle: %{id: id}, handler: handler} = s) do
    receive do
      {^handler, _job, rays, total} ->
        {progress, _} = Progress.atom(%{s.progress | total: total}, rays, now())
        await(%{s | progress: progress})

      {__MODULE__, :tick} ->
        {progress, text} = Progress.tick(s.progress, now())
        if text, do: IO.write(Console.err(), text)
        schedule(progress.mode)
        await(%{s | progress: progress})

      {RingTracer, ^id, {:progress, _, _}} ->
        await(s)

      {RingTracer, ^id, {:frame, n, frame}} ->
        case write_frame(s, n, frame) do
          {:ok, s} ->
            await(s)

          {:error, message} ->
            stop(s)
            {:error, message <> "; " <> kept(length(s.frames))}
        end

      {Signals, signal} ->
        stop(s)
        {:interrupted, signal, length(s.frames)}

      {RingTracer, ^id, result} ->
        IO.write(Console.err(), Progress.finish(s.progress))
        ended(result, s)
    end
  end

  defp write_frame(s, n, frame) do
    path = Frames.path(s.plan, n)

    cond do
      not MapSet.member?(s.left, n) ->
        {:error, "the job sent frame #{n}, which was not asked for or came twice"}

      true ->
        case RingTracer.Image.write(
               path,
               frame.width,
               frame.height,
               frame.pixels,
               [in: s.dir, format: frame.pixel_format] ++ s.mode
             ) do
          :ok ->
            :ok = RingTracer.ack_frame(s.handle, n)

            summary = %{
              number: n,
              completed_us: frame.completed_us,
              elapsed_us: RingTracer.Frame.elapsed_us(frame),
              atoms: frame.atoms,
              rays: frame.rays
            }

            frames = [summary | s.frames]
            progress = Progress.frames(s.progress, length(frames), s.count)

            {:ok, %{s | frames: frames, left: MapSet.delete(s.left, n), progress: progress}}

          {:error, %RingTracer.Error{message: message}} ->
            {:error, message}
        end
    end
  end

  defp ended({:ok, result}, s) do
    if MapSet.size(s.left) == 0,
      do: {:ok, result, Enum.reverse(s.frames)},
      else:
        {:error,
         "the job ended without frames #{s.left |> Enum.sort() |> Enum.join(", ")}; " <>
           kept(length(s.frames))}
  end

  # an option the job refused before any work: a usage error, in the CLI's words
  defp ended({:error, %RingTracer.Error{reason: :invalid_option} = error}, %{frames: []}),
    do: refused(error)

  defp ended({:error, %RingTracer.Error{message: message}}, s),
    do: {:error, message <> "; " <> kept(length(s.frames))}

  defp ended(other, s),
    do: {:error, "the job ended with #{inspect(other)}; " <> kept(length(s.frames))}

  defp refused(%RingTracer.Error{reason: :invalid_option, message: message}),
    do: {:usage, RingTracer.CLI.Render.cli_names(message)}

  defp refused(%RingTracer.Error{message: message}), do: {:error, message}

  defp kept(0), do: "no frame written"

  defp kept(1), do: "the frame written is whole and kept (--continue renders the rest)"
  defp kept(n), do: "the #{n} frames written are whole and kept (--continue renders the rest)"

  defp stop(s) do
    IO.write(Console.err(), Progress.finish(s.progress))
    Signals.cancel(s.handle)
  end

  defp not_interrupted(written) do
    case Signals.pending() do
      nil -> :ok
      signal -> {:interrupted, signal, written}
    end
  end

  # Statistics and timeline, all or none (`RingTracer.Output.write_all/1`).
  defp write_reports(result, job, written) do
    o = job.opts

    writes =
      [
        {o[:stats], &RingTracer.Report.Stats.write(result, &1, &2)},
        {o[:timeline], &RingTracer.Report.Timeline.write(result, &1, &2)}
      ]
      |> Enum.reject(fn {path, _} -> path == nil end)
      |> Enum.map(fn {path, write} ->
        {path, fn dir -> write.(path, in: dir, mode: Console.new_file_mode()) end}
      end)

    case RingTracer.Output.write_all(writes) do
      :ok ->
        :ok

      {:error, %RingTracer.Error{message: message}} ->
        {:error, message <> "; no report written, " <> kept(written)}
    end
  end

  defp report(job, plan, result, frames, load_us) do
    {w, h} = size(result)
    frames = Enum.sort_by(frames, & &1.number)
    [first, last] = Enum.map([hd(frames), List.last(frames)], &Frames.path(plan, &1.number))

    [
      case frames do
        [_] ->
          "wrote #{first} (#{w}x#{h})\n"

        _ ->
          "wrote #{length(frames)} frames (#{w}x#{h}), #{first} to #{last}, " <>
            "#{pace(result, length(frames))}\n"
      end,
      Enum.map(frames, &Report.frame(&1, Path.basename(Frames.path(plan, &1.number)))),
      Report.statistics(result, load_us),
      Report.reports_written(job.opts)
    ]
  end

  defp pace(%{elapsed_us: us}, n), do: Report.pace(us, n)

  defp size(%{width: w, height: h}) when is_integer(w) and is_integer(h), do: {w, h}
  defp size(_result), do: {"?", "?"}

  defp schedule(mode) do
    case Progress.interval(mode) do
      nil -> :ok
      ms -> Process.send_after(self(), {__MODULE__, :tick}, ms)
    end
  end

  defp now, do: System.monotonic_time(:millisecond)
end
