defmodule RingTracer.CLI.Farm.Jobs do
  @moduledoc false
  # The commands about a farm's jobs, each with `--farm HEAD` and the farm's
  # credentials (`RingTracer.CLI.Farm.Client`):
  #
  #   * `ringtracer jobs` — the queue (every job, oldest first) and the workers
  #   * `ringtracer status ID` — one job in full
  #   * `ringtracer wait ID` — until the job ends: 0 done, 1 failed or cancelled
  #   * `ringtracer cancel ID` — a running job's ring stops, a queued one never starts
  #   * `ringtracer fetch ID [--out PATTERN] [--continue] [--wait]` — writes the
  #     frames done to their files (the pattern the job was submitted with,
  #     unless `--out`); `--continue` skips the files already there,
  #     `--wait` goes on until the job ends
  #
  # Exit status as `ringtracer render`'s: 0 ok, 1 failed (no such job, a head
  # that cannot be reached, a job that failed), 2 a usage error, 130/143
  # interrupted.

  alias RingTracer.CLI.{Args, Console, Frames, Paths, Render}
  alias RingTracer.CLI.Farm.{Client, Fetch, Show}
  alias RingTracer.Farm

  @commands ~w(jobs status wait cancel fetch)
  @fetch_switches [out: :string, continue: :boolean, wait: :boolean, quiet: :boolean]
  @aliases [o: :out, q: :quiet]

  @doc "The commands this module runs."
  @spec commands() :: [String.t()]
  def commands, do: @commands

  @doc "The text of `ringtracer COMMAND --help`."
  @spec help(String.t()) :: String.t()
  def help(command) do
    {usage, what, example} = about(command)

    """
    Usage: ringtracer #{usage}

    #{what}

          --farm HEAD         the head's node name (default: $RINGTRACER_FARM)
          --cookie-file PATH  the farm's cookie (default ~/.erlang.cookie)
          --tls DIR           the farm's TLS certificates (default: your own)
          --sname NAME, --name NAME@HOST, --listen ADDR, --ports MIN-MAX, --insecure-plain
    #{if command == "fetch", do: fetch_options(), else: ""}
    Example:
      #{example}

    Exit status: 0 ok, 1 failed (no such job, farm unreachable#{if command in ["wait", "fetch"], do: ", job failed", else: ""}), 2 usage error,
    130/143 interrupted.
    """
  end

  defp about("jobs"),
    do:
      {"jobs --farm HEAD",
       "Lists the farm's jobs, oldest first (id, state, frames done, priority, workers, user,\nscene), then its workers.",
       "ringtracer jobs --farm farm@localhost"}

  defp about("status"),
    do:
      {"status ID --farm HEAD",
       "Shows job ID: its state, frames done and missing, output, priority, workers, times.",
       "ringtracer status 3 --farm farm@localhost"}

  defp about("wait"),
    do:
      {"wait ID --farm HEAD",
       "Waits for job ID to end (no deadline): exit 0 when it is done, 1 when it failed or\nwas cancelled. Writes no file (see fetch).",
       "ringtracer wait 3 --farm farm@localhost && ringtracer fetch 3 --farm farm@localhost"}

  defp about("cancel"),
    do:
      {"cancel ID --farm HEAD",
       "Cancels job ID: a running one's ring stops, a queued one never starts. The frames\ndone stay on the head for fetch.",
       "ringtracer cancel 3 --farm farm@localhost"}

  defp about("fetch"),
    do:
      {"fetch ID --farm HEAD [--out PATTERN] [--continue] [--wait]",
       "Writes the frames of job ID done so far to their files on this machine, each\natomically (whole or absent), named as the job was submitted unless --out.",
       "ringtracer fetch 3 --farm farm@localhost --out frames/o_####.png --continue"}

  defp fetch_options do
    """
      -o, --out PATTERN       where the frames go; a run of # is the frame number
                              (default: the --out the job was submitted with)
          --continue          skip the frames whose file is already there
          --wait              go on until the job ends, each frame as it completes
      -q, --quiet             print nothing but errors
    """
  end

  @doc "Runs `command` with `argv` and returns its exit status."
  @spec run(String.t(), [String.t()]) :: non_neg_integer()
  def run(command, argv) do
    case execute(command, argv) do
      :ok ->
        0

      {:error, status, message} ->
        IO.puts(Console.err(), "ringtracer #{command}: #{message}")
        status
    end
  end

  @doc "Runs `command`: `:ok`, or the exit status and the message to show."
  @spec execute(String.t(), [String.t()]) :: :ok | {:error, pos_integer(), String.t()}
  def execute(command, argv) when command in @commands do
    switches = Client.switches() ++ if(command == "fetch", do: @fetch_switches, else: [])

    case Args.parse(argv, switches, %{}, @aliases) do
      :help ->
        IO.write(help(command))
        :ok

      {:error, message} ->
        {:error, 2, message}

      {:ok, opts, args} ->
        with {:ok, id} <- id(command, args),
             {:ok, head} <- Client.head(opts),
             :ok <- usage_of(RingTracer.Cluster.Distribution.refuse_cookie(opts)),
             :ok <- Client.connect(opts, head) do
          command(command, head, id, opts)
        end
        |> outcome()
    end
  end

  defp id("jobs", []), do: {:ok, nil}
  defp id("jobs", extra), do: {:usage, "jobs takes no argument, got: #{Enum.join(extra, " ")}"}

  defp id(command, [text]) do
    case Integer.parse(text) do
      {id, ""} when id > 0 -> {:ok, id}
      _ -> {:usage, "#{command} takes a job's id (a positive integer), got: #{text}"}
    end
  end

  defp id(command, []), do: {:usage, "give a job's id: ringtracer #{command} ID --farm HEAD"}

  defp id(command, extra),
    do: {:usage, "#{command} takes one job's id, got: #{Enum.join(extra, " ")}"}

  defp command("jobs", head, nil, _opts) do
    with {:ok, overview} <- Farm.overview(head) do
      IO.write([Show.jobs(overview.jobs), Show.workers(overview.workers)])
      :ok
    end
  end

  defp command("status", head, id, _opts) do
    with {:ok, info} <- Farm.status(head, id) do
      IO.write(Show.job(info))
      :ok
    end
  end

  defp command("cancel", head, id, _opts) do
    with :ok <- Farm.cancel(head, id) do
      IO.puts("job #{id} cancelled")
      :ok
    end
  end

  defp command("wait", head, id, _opts) do
    case waiting(head, id) do
      {:ok, %{state: :done} = info} ->
        IO.puts("job #{id} done: #{length(info.done)} of #{length(info.frames)} frames")
        :ok

      {:ok, info} ->
        {:failed, "job #{id} #{info.state}#{if info.error, do: ": #{info.error}", else: ""}"}

      other ->
        other
    end
  end

  defp command("fetch", head, id, opts) do
    with {:ok, info} <- Farm.status(head, id),
         {:ok, out} <- out(info, opts),
         {:ok, plan} <- Fetch.plan(info, out),
         paths = Enum.map(plan.numbers, &Frames.path(plan, &1)),
         :ok <- usage_of(RingTracer.Output.check([{:image, hd(paths)}], [])),
         :ok <- usage_of(RingTracer.Output.check_targets(:image, paths)),
         {:ok, dir} <- RingTracer.Output.open_dir(Path.dirname(hd(paths))),
         skip = skip(plan, dir, opts[:continue]),
         quiet? = opts[:quiet] == true,
         fetch = %{wait: opts[:wait] == true, skip: skip, quiet: quiet?},
         outcome = Fetch.run(head, id, plan, dir, fetch),
         :ok <- fetched(outcome, id, head, fetch.wait) do
      {:ok, info, written} = outcome

      if !quiet? do
        left = length(info.frames) - length(info.done)
        more = if left > 0, do: ", #{left} not done", else: ""

        IO.puts(
          "job #{id} #{info.state}: #{written} frames written, #{length(skip)} there already#{more}"
        )
      end

      :ok
    end
  end

  # Without --wait, writing the frames done is all a fetch does, whatever
  # the job's state; with it, the job must end done, as a submission's.
  defp fetched({:ok, _info, _written}, _id, _head, false), do: :ok
  defp fetched(outcome, id, head, _wait?), do: Fetch.verdict(outcome, id, head)

  defp out(info, opts) do
    case opts[:out] || info.out do
      nil -> {:usage, "job #{info.id} was submitted without an output name: give --out PATTERN"}
      out -> {:ok, Paths.expand(out)}
    end
  end

  defp skip(_plan, _dir, nil), do: []
  defp skip(plan, dir, true), do: elem(Frames.done(plan, dir), 0)

  # Farm.wait with no frame fetched, interruptible.
  defp waiting(head, id) do
    me = self()
    tag = make_ref()

    {pid, ref} =
      spawn_monitor(fn ->
        result =
          with {:ok, info} <- Farm.status(head, id),
               do: Farm.wait(head, id, skip: info.frames)

        send(me, {tag, result})
      end)

    receive do
      {^tag, result} ->
        Process.demonitor(ref, [:flush])
        result

      {:DOWN, ^ref, :process, _, reason} ->
        {:failed, "waiting failed: #{inspect(reason)}"}

      {RingTracer.CLI.Signals, signal} ->
        Process.exit(pid, :kill)
        {:interrupted, {signal, "stopped waiting; job #{id} goes on"}}
    end
  end

  defp outcome(:ok), do: :ok
  defp outcome({:usage, message}), do: {:error, 2, Render.cli_names(message)}
  defp outcome({:failed, message}), do: {:error, 1, message}
  defp outcome({:error, %RingTracer.Error{message: message}}), do: {:error, 1, message}
  defp outcome({:error, message}) when is_binary(message), do: {:error, 1, message}

  defp outcome({:interrupted, {signal, message}}),
    do: {:error, RingTracer.CLI.Signals.exit_status(signal), message}

  defp usage_of({:error, %RingTracer.Error{message: message}}), do: {:usage, message}
  defp usage_of(ok), do: ok
end
