defmodule RingTracer.CLI.Farm.Fetch do
  @moduledoc false
  # A farm job's frames written on this machine: each file as the head stored
  # it (PNG or EXR, the bytes `ringtracer render` writes), atomically, in its
  # folder held open (`RingTracer.Output.write/3`), named by the output
  # pattern (`RingTracer.CLI.Frames`). Used by `ringtracer submit` (which waits
  # for a still, and for a sequence unless `--no-wait`) and `ringtracer fetch`.
  #
  # The frames are fetched by a process of their own, so that an interrupt
  # reaches the command at once: it stops fetching (a file is written whole
  # or not at all) and the job goes on on the farm.

  alias RingTracer.CLI.{Console, Frames, Signals}
  alias RingTracer.Farm

  @typedoc """
  How to fetch: `wait` (until the job ends, each frame as it completes;
  else the frames done now), `skip` (frames not to fetch), `quiet` (print
  nothing but errors).
  """
  @type opts :: %{wait: boolean(), skip: [pos_integer()], quiet: boolean()}

  @typedoc "What fetching came to: the job as it stood at the end, and the frames written."
  @type outcome ::
          {:ok, Farm.JobInfo.t(), non_neg_integer()}
          | {:error, String.t()}
          | {:interrupted, :sigint | :sigterm, non_neg_integer()}

  @doc """
  Fetches the frames of job `id` on `head` into the files `plan` names, in
  `dir` (their folder, from `RingTracer.Output.open_dir/1`).
  """
  @spec run(node(), pos_integer(), Frames.t(), RingTracer.Output.dir(), opts()) :: outcome()
  def run(head, id, plan, dir, opts) do
    me = self()
    tag = make_ref()
    mode = Console.new_file_mode()
    wanted = MapSet.new(plan.numbers)

    write = fn n, bytes ->
      if MapSet.member?(wanted, n) do
        path = Frames.path(plan, n)

        with :ok <- RingTracer.Output.write(path, bytes, in: dir, mode: mode) do
          send(me, {tag, :wrote, n, path})
          :ok
        end
      else
        :ok
      end
    end

    fetch =
      if opts.wait,
        do: fn -> Farm.wait(head, id, on_frame: write, skip: opts.skip) end,
        else: fn -> now(head, id, opts.skip, write) end

    {pid, ref} = spawn_monitor(fn -> send(me, {tag, :result, fetch.()}) end)

    await(%{
      tag: tag,
      pid: pid,
      ref: ref,
      quiet: opts.quiet,
      written: 0,
      total: length(plan.numbers)
    })
  end

  # The frames done now, each fetched once.
  defp now(head, id, skip, write) do
    with {:ok, info} <- Farm.status(head, id) do
      Enum.reduce_while(info.done -- skip, {:ok, info}, fn n, acc ->
        with {:ok, bytes} <- Farm.frame(head, id, n),
             :ok <- write.(n, bytes) do
          {:cont, acc}
        else
          {:error, _} = error -> {:halt, error}
        end
      end)
    end
  end

  defp await(%{tag: tag, ref: ref} = s) do
    receive do
      {^tag, :wrote, n, path} ->
        if !s.quiet, do: IO.puts("wrote #{path} (frame #{n})")
        await(%{s | written: s.written + 1})

      {^tag, :result, result} ->
        Process.demonitor(ref, [:flush])
        drain(%{s | pid: nil}, result)

      {:DOWN, ^ref, :process, _, reason} ->
        {:error, "fetching the frames failed: #{inspect(reason)}"}

      {Signals, signal} ->
        Process.demonitor(ref, [:flush])
        Process.exit(s.pid, :kill)
        {:interrupted, signal, s.written}
    end
  end

  # The frames written before the result came, then the result.
  defp drain(%{tag: tag} = s, result) do
    receive do
      {^tag, :wrote, n, path} ->
        if !s.quiet, do: IO.puts("wrote #{path} (frame #{n})")
        drain(%{s | written: s.written + 1}, result)
    after
      0 ->
        case result do
          {:ok, info} -> {:ok, info, s.written}
          {:error, %RingTracer.Error{message: message}} -> {:error, message}
        end
    end
  end

  @doc """
  The plan of a job's files: its frames, named by `out` (a run of `#` for
  the frame number; needed for more than one frame).
  """
  @spec plan(Farm.JobInfo.t(), Path.t()) :: {:ok, Frames.t()} | {:usage, String.t()}
  def plan(info, out) do
    ext = out |> Path.extname() |> String.downcase()

    if ext != ".#{info.format}" do
      {:usage,
       "--out #{out}: job #{info.id}'s frames are #{String.upcase(to_string(info.format))} " <>
         "files; give a .#{info.format} name"}
    else
      frames = info.frames
      sequence? = length(frames) > 1

      case RingTracer.Output.Pattern.parse(out) do
        {:ok, pattern} ->
          {:ok, %Frames{numbers: frames, out: out, pattern: pattern, sequence?: sequence?}}

        {:error, :none} when not sequence? ->
          {:ok, %Frames{numbers: frames, out: out, pattern: nil, sequence?: false}}

        {:error, :none} ->
          {:usage,
           "--out #{out}: job #{info.id} has #{length(frames)} frames; a run of # in the " <>
             "file name stands for the frame number (f_####.#{info.format})"}

        {:error, :many} ->
          Frames.check_out(out)
      end
    end
  end

  @doc """
  What fetching came to, as a command's outcome: `:ok` when the job ended
  done, else why not, in words (an interrupt with its signal).
  """
  @spec verdict(outcome(), pos_integer(), node()) ::
          :ok
          | {:failed, String.t()}
          | {:interrupted, {:sigint | :sigterm, String.t()}}
  def verdict(outcome, id, head) do
    case outcome do
      {:ok, %{state: :done}, _written} ->
        :ok

      {:ok, info, written} ->
        why = if info.error, do: ": #{info.error}", else: ""
        {:failed, "job #{id} #{info.state}#{why}; #{frames(written)} written"}

      {:error, message} ->
        {:failed, message}

      {:interrupted, signal, written} ->
        {:interrupted,
         {signal,
          "stopped waiting; #{frames(written)} written, whole; job #{id} goes on " <>
            "(ringtracer fetch #{id} --farm #{head} --continue gets the rest)"}}
    end
  end

  defp frames(1), do: "1 frame"
  defp frames(n), do: "#{n} frames"
end
