defmodule RingTracer.Farm do
  @moduledoc """
  A render farm: a head that keeps a durable queue of jobs, workers that
  join it and leave at any time, and clients that submit scenes and get
  their frames back. A job is a still or a sequence
  (`RingTracer.render_sequence/2`); the head runs it through one ring over
  the workers the policy gives it (`RingTracer.Farm.Policy`), and a worker
  that joins while it runs joins its ring. docs/farm.md has the whole
  picture.

  `head` below is the head's node name (an atom such as
  `:"farm@localhost"`); this node must be able to reach it (distributed,
  with the farm's cookie and TLS certificates). Every call has a deadline:
  a head that does not answer within `:timeout` (default #{10_000} ms) is
  `{:error, %RingTracer.Error{reason: :farm_unreachable}}`.

  A job never reads a file on the head or on a worker: the scene's bytes,
  and those of every file it references, are read here (confined as
  renders are) and travel with the submission. The head stores each frame
  as it completes (PNG or EXR), atomically, and records it in Mnesia; a
  frame recorded is never rendered again, even after `kill -9` of the head.
  """

  alias RingTracer.{Error, Names, Options, Scene}
  alias RingTracer.Farm.{Dashboard, Head, Job, JobInfo, Member, Runner, WorkerInfo}

  @timeout 10_000
  @rewatch_ms 500
  @farm_keys [:user, :priority, :tags, :max_workers, :format, :out, :frames, :timeout]

  @doc """
  Starts a farm's head on this node, which should be distributed under a
  name that stays the same across restarts (Mnesia's files belong to it).

  ## Options

    * `:dir` — the head's folder (required): Mnesia's files and the frames
      done; made with mode 0700 if missing, and refused if it is not this
      user's or others can change it
    * `:policy` — how workers are shared between jobs, a module of
      `RingTracer.Farm.Policy` (default `RingTracer.Farm.Policy.Fair`)
    * `:dashboard` — a web page of the farm's workers, jobs and queue, with
      a link to each running job's live preview
      (`RingTracer.Farm.Dashboard`): `true` (a free port on 127.0.0.1) or
      `[port: p, listen: address]`; its address, with a random token, is
      `dashboard_url/1`'s, and stays the same when the head restarts
      (default `false`: none)
  """
  @spec start_head(keyword()) :: {:ok, pid()} | {:error, Error.t()}
  def start_head(opts) do
    with {:ok, dir} <- fetch_string(opts, :dir),
         policy = opts[:policy] || RingTracer.Farm.Policy.Fair,
         :ok <- behaviour(policy),
         {:ok, dashboard} <- dashboard(Keyword.get(opts, :dashboard, false)) do
      spec = %{
        id: Names.farm(),
        type: :supervisor,
        start:
          {Supervisor, :start_link,
           [
             dashboard ++
               [
                 {DynamicSupervisor, name: Names.farm_runners(), strategy: :one_for_one},
                 {Head, dir: dir, policy: policy}
               ],
             [strategy: :one_for_all, name: Names.farm(), max_restarts: 3, max_seconds: 5]
           ]}
      }

      case Supervisor.start_child(RingTracer.Supervisor, spec) do
        {:ok, pid} ->
          {:ok, pid}

        {:error, {:already_started, _}} ->
          {:error, Error.new(:farm, "a farm head runs on this node already")}

        # The head's or the dashboard's own words.
        {:error, {{:shutdown, {:failed_to_start_child, _, %Error{} = e}}, _}} ->
          Supervisor.delete_child(RingTracer.Supervisor, Names.farm())
          {:error, e}

        {:error, {:shutdown, {:failed_to_start_child, _, %Error{} = e}}} ->
          Supervisor.delete_child(RingTracer.Supervisor, Names.farm())
          {:error, e}

        {:error, reason} ->
          Supervisor.delete_child(RingTracer.Supervisor, Names.farm())
          {:error, Error.new(:farm, "the head could not start: #{inspect(reason)}")}
      end
    end
  end

  # The dashboard's child, first: it serves before any runner starts, and
  # runners start a job's preview only where it runs.
  defp dashboard(false), do: {:ok, []}

  defp dashboard(option) do
    with {:ok, opts} <- Dashboard.options(option), do: {:ok, [{Dashboard, opts}]}
  end

  @doc """
  The address of the dashboard of the head on `head` (default this node),
  with its token: open it in a browser. An error when that head was
  started without `:dashboard`.
  """
  @spec dashboard_url(node()) :: {:ok, String.t()} | {:error, Error.t()}
  def dashboard_url(head \\ node()) when is_atom(head), do: Dashboard.url(head)

  @doc "Stops this node's head (its running rings stop; the queue stays in its folder)."
  @spec stop_head() :: :ok
  def stop_head do
    _ = Supervisor.terminate_child(RingTracer.Supervisor, Names.farm())
    _ = Supervisor.delete_child(RingTracer.Supervisor, Names.farm())
    RingTracer.Farm.Store.close()
  end

  @doc """
  Makes this node a worker of the farm whose head is `head`: it joins now
  or as soon as the head can be reached, and joins again by itself
  whenever the head restarts. A head of another build
  (`RingTracer.Cluster.Build`) refuses it: the worker logs the refusal,
  naming both builds, and asks again every few seconds.

  ## Options

    * `:tags` — strings a job may ask its workers to have (`["big-mem"]`)
    * `:slots` — children this worker hosts for a job (default: its dirty
      CPU schedulers, one per core)
    * `:speed` — emulates a machine this many times slower (a number >= 1,
      default 1): each child here waits after each atom, for benchmarks and
      soaks on one machine (`RingTracer.Job.Slowdown`)
  """
  @spec join(node(), keyword()) :: {:ok, pid()} | {:error, Error.t()}
  def join(head, opts \\ []) when is_atom(head) do
    slots = opts[:slots] || :erlang.system_info(:dirty_cpu_schedulers)
    tags = opts[:tags] || []
    speed = Keyword.get(opts, :speed, 1)

    cond do
      not RingTracer.Job.Slowdown.factor?(speed) ->
        invalid(
          ":speed must be a number from 1 to #{RingTracer.Job.Slowdown.max()}, got: #{inspect(speed)}"
        )

      not (is_integer(slots) and slots > 0) ->
        invalid(":slots must be a positive integer, got: #{inspect(slots)}")

      not (is_list(tags) and Enum.all?(tags, &tag?/1)) ->
        invalid(":tags must be a list of tags (letters, digits, - and _), got: #{inspect(tags)}")

      true ->
        Application.put_env(:ring_tracer, :node_speed, speed)
        spec = {Member, head: head, tags: tags, slots: slots, speed: speed}

        case Supervisor.start_child(RingTracer.Supervisor, spec) do
          {:ok, pid} -> {:ok, pid}
          {:error, {:already_started, _}} -> invalid("this node is a farm worker already")
          {:error, :already_present} -> restart_member()
          {:error, reason} -> {:error, Error.new(:farm, "could not join: #{inspect(reason)}")}
        end
    end
  end

  defp restart_member do
    Supervisor.delete_child(RingTracer.Supervisor, Member)
    {:error, Error.new(:farm, "a farm membership had ended; join again")}
  end

  @doc "Ends this worker's membership of its farm (its children stop with their jobs' rings)."
  @spec leave() :: :ok
  def leave do
    _ = Supervisor.terminate_child(RingTracer.Supervisor, Member)
    _ = Supervisor.delete_child(RingTracer.Supervisor, Member)
    :ok
  end

  @doc """
  Queues a scene on the farm and returns the job's id once the head has it
  on disk. A head of another build (`RingTracer.Cluster.Build`) is not
  given the job: an error of reason `:build_mismatch` naming both builds.

  `scene` is a path, read here (confined as `RingTracer.render/2` reads
  it, `:allow_dirs` included), or a loaded `RingTracer.Scene`.

  ## Options

  The render options of `RingTracer.render_sequence/2` (`:width`,
  `:height`, `:atoms`, `:strategy`, ...) but those the farm sets from its
  workers (`:nodes`, `:local`, `:children`, `:children_per_node`,
  `:window`, `:ack`), and:

    * `:frames` — the scene's frames (a range or an ascending list, from
      1; default every frame; a scene without animation has one)
    * `:format` — `:png` (default) or `:exr`, the files the head stores
    * `:out` — the output pattern the submitter wants (`"f_####.png"`),
      kept with the job for `wait` and `fetch`; its extension picks
      `:format` when that is not given
    * `:user` — who submits, for fair shares (default `$USER@host`)
    * `:priority` — an integer, higher first (default 0)
    * `:tags` — tags every worker of the job must have
    * `:max_workers` — the most workers the job may use
    * `:timeout` — how long to wait for the head, in ms (default #{@timeout})
  """
  @spec submit(node(), Path.t() | Scene.t(), keyword()) ::
          {:ok, pos_integer()} | {:error, Error.t()}
  def submit(head, scene, opts \\ []) do
    {farm, render} = Keyword.split(opts, @farm_keys)

    with :ok <- refused(render),
         {:ok, _} <- Options.validate(render),
         {:ok, scene} <- load(scene, render),
         {:ok, frames, _window, _ack} <-
           RingTracer.Sequence.options(
             Keyword.take(farm, [:frames]),
             scene.frames,
             scene.source.name
           ),
         # Sequence.options gives the layout's frames, from 0
         frames = Enum.map(frames, &(&1 + 1)),
         {:ok, job} <- job(scene, frames, farm, Keyword.drop(render, [:allow_dirs])),
         :ok <- same_build(head, farm[:timeout]) do
      call(head, {:submit, job}, farm[:timeout])
    end
  end

  # A job is this build's (its options, its scene's source): a head of
  # another build is not given it.
  defp same_build(head, timeout) do
    case RingTracer.Cluster.Build.check(head, timeout: timeout || @timeout) do
      :ok ->
        :ok

      {:error, %Error{} = error} ->
        {:error, error}

      {:error, {:call, {:erpc, :timeout}}} ->
        {:error, Error.new(:farm_unreachable, "the farm head #{head} did not answer in time")}

      {:error, {:call, _}} ->
        {:error, Error.new(:farm_unreachable, "the farm head #{head} cannot be reached")}
    end
  end

  defp refused(render) do
    case Enum.find(
           Runner.farm_set() ++ [:frame, :region, :progress, :preview],
           &Keyword.has_key?(render, &1)
         ) do
      nil -> :ok
      key -> invalid("option #{inspect(key)} is not one of a farm job's: the farm sets it")
    end
  end

  defp load(%Scene{} = scene, _opts), do: {:ok, scene}

  defp load(path, opts) when is_binary(path),
    do: Scene.load(path, Keyword.take(opts, [:allow_dirs]))

  defp job(scene, frames, farm, render) do
    with {:ok, format} <- format(farm),
         {:ok, user} <- user(farm[:user]),
         {:ok, priority} <- integer(farm, :priority, 0),
         {:ok, tags} <- tags(farm[:tags] || []),
         {:ok, max} <- max_workers(farm[:max_workers]) do
      {width, height} = Scene.image_size(scene, render[:width], render[:height])

      {:ok,
       %Job{
         id: 0,
         user: user,
         source: scene.source,
         options: render,
         frames: frames,
         format: format,
         width: width,
         height: height,
         out: farm[:out],
         priority: priority,
         tags: tags,
         max_workers: max
       }}
    end
  end

  defp format(farm) do
    case {farm[:format], farm[:out] && String.downcase(Path.extname(farm[:out]))} do
      {f, _} when f in [:png, :exr] -> {:ok, f}
      {nil, ".exr"} -> {:ok, :exr}
      {nil, _} -> {:ok, :png}
      {other, _} -> invalid(":format must be :png or :exr, got: #{inspect(other)}")
    end
  end

  defp user(nil) do
    name = System.get_env("USER") || "user"
    {:ok, host} = :inet.gethostname()
    {:ok, "#{name}@#{host}"}
  end

  defp user(user) when is_binary(user) and byte_size(user) in 1..64, do: {:ok, user}
  defp user(other), do: invalid(":user must be a string of 1 to 64 bytes, got: #{inspect(other)}")

  defp integer(opts, key, default) do
    case Keyword.get(opts, key, default) do
      i when is_integer(i) -> {:ok, i}
      other -> invalid("#{inspect(key)} must be an integer, got: #{inspect(other)}")
    end
  end

  defp tags(tags) do
    if is_list(tags) and Enum.all?(tags, &tag?/1),
      do: {:ok, Enum.uniq(tags)},
      else:
        invalid(":tags must be a list of tags (letters, digits, - and _), got: #{inspect(tags)}")
  end

  defp tag?(tag), do: is_binary(tag) and tag =~ ~r/\A[A-Za-z0-9_-]{1,64}\z/

  defp max_workers(nil), do: {:ok, nil}
  defp max_workers(n) when is_integer(n) and n > 0, do: {:ok, n}

  defp max_workers(other),
    do: invalid(":max_workers must be a positive integer, got: #{inspect(other)}")

  @doc "Every job the head knows, in the order they were submitted."
  @spec jobs(node(), keyword()) :: {:ok, [JobInfo.t()]} | {:error, Error.t()}
  def jobs(head, opts \\ []), do: call(head, :jobs, opts[:timeout])

  @doc "One job."
  @spec status(node(), pos_integer(), keyword()) :: {:ok, JobInfo.t()} | {:error, Error.t()}
  def status(head, id, opts \\ []), do: call(head, {:status, id}, opts[:timeout])

  @doc "The workers that have joined the head."
  @spec workers(node(), keyword()) :: {:ok, [WorkerInfo.t()]} | {:error, Error.t()}
  def workers(head, opts \\ []), do: call(head, :workers, opts[:timeout])

  @doc """
  Workers and jobs at once (the dashboard's view), and `:stored_twice`, how
  many frames were ever stored after they were done (0: the farm never
  traced a frame twice).
  """
  @spec overview(node(), keyword()) ::
          {:ok,
           %{workers: [WorkerInfo.t()], jobs: [JobInfo.t()], stored_twice: non_neg_integer()}}
          | {:error, Error.t()}
  def overview(head, opts \\ []), do: call(head, :overview, opts[:timeout])

  @doc """
  Cancels a job: a running one's ring stops, a queued one never starts.
  Frames done stay on the head. A job that has ended is an error.
  """
  @spec cancel(node(), pos_integer(), keyword()) :: :ok | {:error, Error.t()}
  def cancel(head, id, opts \\ []), do: call(head, {:cancel, id}, opts[:timeout])

  @doc """
  Subscribes the calling process to a job: it gets `{RingTracer.Farm, id,
  {:frame, n}}` as each frame completes from now on, and `{RingTracer.Farm,
  id, {:end, state, error}}` when the job ends (at once if it has ended).
  """
  @spec subscribe(node(), pos_integer(), keyword()) :: :ok | {:error, Error.t()}
  def subscribe(head, id, opts \\ []), do: call(head, {:subscribe, id, self()}, opts[:timeout])

  @doc "Frame `n` of a job, as the head stores it: a whole PNG or EXR file's bytes."
  @spec frame(node(), pos_integer(), pos_integer(), keyword()) ::
          {:ok, binary()} | {:error, Error.t()}
  def frame(head, id, n, opts \\ []), do: call(head, {:frame, id, n}, opts[:timeout])

  @doc """
  Waits for a job to end, handing each of its frames to `:on_frame` once:
  those done already, then each as it completes. Returns the job's final
  `RingTracer.Farm.JobInfo`.

  ## Options

    * `:on_frame` — `fn n, bytes -> :ok | {:error, Error.t()} end` (default:
      nothing); an error stops the wait and is returned
    * `:skip` — frames not to fetch (the caller has them already)
    * `:timeout` — the longest wait for the whole job, in ms or `:infinity`
      (default); each call to the head has its own 10 s deadline

  A head that goes meanwhile (restarted, `kill -9` included) is waited
  for, and subscribed to again once it is back.
  """
  @spec wait(node(), pos_integer(), keyword()) :: {:ok, JobInfo.t()} | {:error, Error.t()}
  def wait(head, id, opts \\ []) do
    on_frame = opts[:on_frame] || fn _, _ -> :ok end
    deadline = deadline(opts[:timeout] || :infinity)
    # A head that cannot be reached at first is an error; once subscribed,
    # one that goes is waited for.
    with :ok <- subscribe(head, id),
         do: watch(head, id, MapSet.new(opts[:skip] || []), on_frame, deadline)
  end

  # Subscribed: watches the head, fetching the frames done so far, then each
  # as it completes. A head lost at any point (its subscribers gone with it)
  # is subscribed to again once it is back; the frames handed over stay
  # handed over.
  defp watch(head, id, seen, on_frame, deadline) do
    ref = Process.monitor(Names.farm_head(head))

    with {:ok, info} <- status(head, id),
         {:ok, seen} <- fetch_each(head, id, info.done, seen, on_frame) do
      wait_loop(head, id, ref, seen, on_frame, deadline)
    else
      error -> lost(error, head, id, ref, seen, on_frame, deadline)
    end
  end

  defp wait_loop(head, id, ref, seen, on_frame, deadline) do
    receive do
      {RingTracer.Farm, ^id, {:frame, n}} ->
        case fetch_each(head, id, [n], seen, on_frame) do
          {:ok, seen} -> wait_loop(head, id, ref, seen, on_frame, deadline)
          error -> lost(error, head, id, ref, seen, on_frame, deadline)
        end

      {RingTracer.Farm, ^id, {:end, _state, _error}} ->
        # Frames that completed before the subscription but after the
        # first status, if any, then the job as it ended. An end that the
        # head does not confirm (left in this mailbox by an earlier head's
        # job of the same id) is not this job's.
        with {:ok, info} <- status(head, id),
             {:ok, seen} <- fetch_each(head, id, info.done, seen, on_frame) do
          if Job.ended_state?(info.state) do
            Process.demonitor(ref, [:flush])
            {:ok, info}
          else
            wait_loop(head, id, ref, seen, on_frame, deadline)
          end
        else
          error -> lost(error, head, id, ref, seen, on_frame, deadline)
        end

      {:DOWN, ^ref, :process, _, _} ->
        rewatch(head, id, seen, on_frame, deadline)
    after
      remaining(deadline) ->
        {:error, Error.new(:timeout, "job #{id} did not end in time")}
    end
  end

  # A call that failed while watching: a head that cannot be reached is
  # waited for (with the frames handed over before the failure); any other
  # error ends the wait.
  defp lost(error, head, id, ref, seen, on_frame, deadline) do
    Process.demonitor(ref, [:flush])

    case error do
      {:error, %Error{reason: :farm_unreachable}, seen} ->
        rewatch(head, id, seen, on_frame, deadline)

      {:error, %Error{reason: :farm_unreachable}} ->
        rewatch(head, id, seen, on_frame, deadline)

      {:error, error, _seen} ->
        {:error, error}

      {:error, _} ->
        error
    end
  end

  defp rewatch(head, id, seen, on_frame, deadline) do
    receive do
    after
      min(@rewatch_ms, remaining(deadline)) -> :ok
    end

    case remaining(deadline) do
      0 ->
        {:error, Error.new(:timeout, "job #{id} did not end in time")}

      _ ->
        case subscribe(head, id) do
          :ok ->
            watch(head, id, seen, on_frame, deadline)

          {:error, %Error{reason: :farm_unreachable}} ->
            rewatch(head, id, seen, on_frame, deadline)

          error ->
            error
        end
    end
  end

  # {:ok, seen}, or {:error, error, seen}: the frames handed over before the
  # error are seen.
  defp fetch_each(head, id, numbers, seen, on_frame) do
    Enum.reduce_while(numbers, {:ok, seen}, fn n, {:ok, seen} ->
      if MapSet.member?(seen, n) do
        {:cont, {:ok, seen}}
      else
        with {:ok, bytes} <- frame(head, id, n),
             :ok <- on_frame.(n, bytes) do
          {:cont, {:ok, MapSet.put(seen, n)}}
        else
          {:error, error} -> {:halt, {:error, error, seen}}
        end
      end
    end)
  end

  defp deadline(:infinity), do: :infinity
  defp deadline(ms), do: System.monotonic_time(:millisecond) + ms

  defp remaining(:infinity), do: :infinity
  defp remaining(deadline), do: max(0, deadline - System.monotonic_time(:millisecond))

  defp call(head, message, timeout) do
    GenServer.call(Names.farm_head(head), message, timeout || @timeout)
  catch
    :exit, {:timeout, _} ->
      {:error, Error.new(:farm_unreachable, "the farm head #{head} did not answer in time")}

    :exit, _ ->
      {:error, Error.new(:farm_unreachable, "the farm head #{head} cannot be reached")}
  end

  defp fetch_string(opts, key) do
    case opts[key] do
      s when is_binary(s) and s != "" -> {:ok, s}
      other -> invalid("#{inspect(key)} must be a path, got: #{inspect(other)}")
    end
  end

  defp behaviour(policy) do
    if is_atom(policy) and Code.ensure_loaded?(policy) and function_exported?(policy, :assign, 1),
      do: :ok,
      else: invalid(":policy must be a module of RingTracer.Farm.Policy, got: #{inspect(policy)}")
  end

  defp invalid(message), do: {:error, Error.new(:invalid_option, message)}
end
