defmodule RingTracer.CLI.Farm.Show do
  @moduledoc false
  # A farm's jobs and workers as `ringtracer jobs` and `ringtracer status`
  # print them: plain text, one job a line in the list, pure functions of
  # `RingTracer.Farm.JobInfo` and `RingTracer.Farm.WorkerInfo`.

  alias RingTracer.Farm.{JobInfo, WorkerInfo}

  @doc """
  The queue as a table: one line per job, oldest first.

      iex> job = %RingTracer.Farm.JobInfo{id: 3, user: "ann", state: :running, scene: "orbit.toml",
      ...>   frames: [1, 2, 3, 4], done: [1], workers: [:"w1@localhost"]}
      iex> RingTracer.CLI.Farm.Show.jobs([job]) |> IO.iodata_to_binary()
      "  ID  STATE      FRAMES  PRI  WORKERS  USER  SCENE\\n   3  running    1/4       0        1  ann   orbit.toml\\n"
  """
  @spec jobs([JobInfo.t()]) :: iodata()
  def jobs([]), do: "no jobs on this farm\n"

  def jobs(jobs) do
    user_w = jobs |> Enum.map(&String.length(&1.user)) |> Enum.max() |> max(4)

    header = [
      "  ID  STATE      FRAMES  PRI  WORKERS  ",
      String.pad_trailing("USER", user_w),
      "  SCENE\n"
    ]

    [
      header
      | Enum.map(jobs, fn j ->
          [
            String.pad_leading(Integer.to_string(j.id), 4),
            "  ",
            String.pad_trailing(Atom.to_string(j.state), 9),
            "  ",
            String.pad_trailing("#{length(j.done)}/#{length(j.frames)}", 6),
            "  ",
            String.pad_leading(Integer.to_string(j.priority), 3),
            "  ",
            String.pad_leading(Integer.to_string(length(j.workers)), 7),
            "  ",
            String.pad_trailing(j.user, user_w),
            "  ",
            j.scene || "-",
            "\n"
          ]
        end)
    ]
  end

  @doc """
  The workers that joined, one a line.

      iex> w = %RingTracer.Farm.WorkerInfo{node: :"w1@localhost", slots: 2, speed: 1, job: 3, tags: ["gpu"]}
      iex> RingTracer.CLI.Farm.Show.workers([w]) |> IO.iodata_to_binary()
      "workers (1):\\n  w1@localhost  2 slots  speed 1  job 3  tags gpu\\n"
  """
  @spec workers([WorkerInfo.t()]) :: iodata()
  def workers([]), do: "workers: none has joined\n"

  def workers(workers) do
    node_w = workers |> Enum.map(&String.length(Atom.to_string(&1.node))) |> Enum.max()

    [
      "workers (#{length(workers)}):\n"
      | Enum.map(workers, fn w ->
          [
            "  ",
            String.pad_trailing(Atom.to_string(w.node), node_w),
            "  #{w.slots} slot#{if w.slots == 1, do: "", else: "s"}",
            "  speed #{w.speed}",
            "  #{if w.job, do: "job #{w.job}", else: "idle"}",
            if(w.tags == [], do: "", else: "  tags #{Enum.join(w.tags, ",")}"),
            "\n"
          ]
        end)
    ]
  end

  @doc """
  One job in full, a field a line.

      iex> job = %RingTracer.Farm.JobInfo{id: 3, user: "ann", state: :done, scene: "orbit.toml",
      ...>   width: 64, height: 48, format: :png, out: "/tmp/f_####.png", frames: [1, 2, 3, 5], done: [1, 2, 3, 5]}
      iex> RingTracer.CLI.Farm.Show.job(job) |> IO.iodata_to_binary() =~ "frames:    4 done of 4 (1-3, 5)"
      true
  """
  @spec job(JobInfo.t()) :: iodata()
  def job(%JobInfo{} = j) do
    missing = j.frames -- j.done

    [
      "job #{j.id}: #{j.state}#{if j.error, do: " (#{j.error})", else: ""}\n",
      "  user:      #{j.user}\n",
      "  scene:     #{j.scene || "-"}#{size(j)}\n",
      "  frames:    #{length(j.done)} done of #{length(j.frames)} (#{ranges(j.frames)})\n",
      if(missing != [] and j.done != [], do: "  missing:   #{ranges(missing)}\n", else: ""),
      "  output:    #{j.out || "-"}#{if j.format, do: " (#{j.format})", else: ""}\n",
      "  priority:  #{j.priority}#{tags(j.tags)}#{cap(j.max_workers)}\n",
      "  workers:   #{if j.workers == [], do: "none", else: Enum.join(j.workers, ", ")}\n",
      times(j)
    ]
  end

  defp size(%JobInfo{width: w, height: h}) when is_integer(w) and is_integer(h),
    do: " (#{w}x#{h})"

  defp size(_), do: ""

  defp tags([]), do: ""
  defp tags(tags), do: "; tags #{Enum.join(tags, ",")}"

  defp cap(nil), do: ""
  defp cap(n), do: "; at most #{n} workers"

  defp times(j) do
    [submitted_at: "submitted", started_at: "started", finished_at: "finished"]
    |> Enum.flat_map(fn {key, label} ->
      case Map.fetch!(j, key) do
        nil -> []
        ms -> ["  #{String.pad_trailing(label <> ":", 10)} #{time(ms)}\n"]
      end
    end)
  end

  defp time(ms) do
    ms
    |> DateTime.from_unix!(:millisecond)
    |> DateTime.truncate(:second)
    |> DateTime.to_iso8601()
  end

  @doc """
  Ascending numbers as ranges.

      iex> RingTracer.CLI.Farm.Show.ranges([1, 2, 3, 7, 9, 10])
      "1-3, 7, 9-10"
      iex> RingTracer.CLI.Farm.Show.ranges([])
      "none"
  """
  @spec ranges([integer()]) :: String.t()
  def ranges([]), do: "none"

  def ranges(numbers) do
    numbers
    |> Enum.chunk_while(
      nil,
      fn
        n, nil -> {:cont, {n, n}}
        n, {a, b} when n == b + 1 -> {:cont, {a, n}}
        n, run -> {:cont, run, {n, n}}
      end,
      fn run -> {:cont, run, nil} end
    )
    |> Enum.map_join(", ", fn
      {a, a} -> "#{a}"
      {a, b} -> "#{a}-#{b}"
    end)
  end
end
