defmodule RingTracer do
  @moduledoc """
  RingTracer renders one image with many BEAM processes, possibly on many
  nodes, balanced by the ring model of Câmara and Guedes: a parent, N
  children linked in a ring, one grandchild per child tracing one atom at a
  time in a native Whitted ray tracer.

      iex> {:ok, result} = RingTracer.render("priv/scenes/tetra_s1.nff", children: 3, atoms: 4, width: 32, height: 24)
      iex> byte_size(result.pixels)
      32 * 24 * 12
      iex> Enum.sum(Enum.map(result.children, & &1.traced))
      12

  See `render/2` for the options and `RingTracer.Image` to write files.
  """

  alias RingTracer.{Error, Layout, Native, Options, Result, Scene, SceneCache, Settings}
  alias RingTracer.Job.{Parent, Spec}

  @job_call_timeout 5_000

  @doc """
  Renders the scene file at `path` (`.nff`, `.toml` or `.obj`), or a scene
  already loaded with `RingTracer.Scene.load/2`, and returns the image and
  the job's statistics.

  ## Options

    * `:children` — ring size N (default: schedulers online)
    * `:atoms` — atoms per child K (default #{RingTracer.Options.default(:atoms)})
    * `:width`, `:height` — image size (default: the scene's; one of them
      alone keeps the scene's aspect ratio)
    * `:depth` — ray-tree depth limit, eye ray = 1 (default #{RingTracer.Settings.shown_default(:depth)})
    * `:cutoff` — adaptive cut-off: a branch whose weight falls below it is
      not traced (default #{RingTracer.Settings.shown_default(:cutoff)}; 0 disables)
    * `:samples` — S x S stratified samples per pixel (default #{RingTracer.Settings.shown_default(:samples)})
    * `:frame` — which frame of an animated scene to render, from 1 to the
      scene's `:frames`, at POV-Ray's clock for it (default 1; see
      docs/scene-format.md, "Animation"). A still has one frame
    * `:spd` — SPD testing procedure: rays through pixel corners, no
      cut-off (default #{RingTracer.Settings.shown_default(:spd)})
    * `:region` — trace only part of the image, `{x0, y0, x1, y1}`: pixels
      (integers, x1 and y1 excluded) or fractions (floats 0.0 to 1.0, like
      POV-Ray's `+SC +EC +SR +ER`); the result is that part, with exactly the
      pixels the whole render has there
    * `:strategy` — `:ring` (default), `:static`, `:master` or `:steal`,
      a name with its options (`{:ring, split: true}`), or a strategy of
      your own as `{module, options}` (see `RingTracer.Strategy`). The
      ring's options: `:hold_after` — hops an offer walks before it may
      wait at a child about to run out (default
      #{RingTracer.Strategy.Ring.HelpOffer.default_hold_after()}); `:aim` — whether an
      idle child sends its offer straight to the sibling it expects to stay
      busy longest rather than to its left sibling (default: on strips of
      one image yes, otherwise no; a sequence of several frames refuses
      `aim: true`); `:split` —
      adaptive atoms, cut into pieces near the end of a job (default false:
      they do not yet pay for their messages on this machine). The image is
      the same whatever the strategy
    * `:layout` — which atoms each child owns at the start: `:strips` (the
      paper's contiguous strips, default) or `:interleaved` (child i owns
      atoms i, i + N, i + 2N, ...; see `RingTracer.Layout`). The image is
      the same; the balance is not
    * `:speeds` — slowdown factors of the children, e.g. `[1, 1, 4, 1]`
      makes child 2 four times slower (cyclic; default all 1)
    * `:nodes` — other nodes to place children on, round robin with this
      one (default: none). Each is connected to and checked first: it must
      run `:ring_tracer` (e.g. `mix ring_tracer.worker`) with the same cookie
    * `:local` — with `:nodes`, whether this node hosts children too
      (default true)
    * `:children_per_node` — with `:nodes`, that many children on each node
      instead of `:children` round robin
    * `:progress` — a pid that gets `{RingTracer, job_id, {:progress, done,
      total}}` as atoms arrive (for every atom of jobs of up to 1,000
      atoms, then every thousandth of the job, and always for the last)
    * `:kernel` — what traces the atoms, `{module, options}` (default the
      native ray tracer, `RingTracer.Kernel.Native`; see `RingTracer.Kernel`)
    * `:timeout` — milliseconds, or `:infinity` (default)
    * `:liveness` — with `:nodes`, milliseconds after which a node that
      does not answer (frozen, hung) is disconnected and its atoms traced
      elsewhere (default 10_000; see `RingTracer.Cluster.Liveness`)
    * `:allow_dirs` — folders besides the scene's own that the scene may read
      referenced files from (default none; see `RingTracer.Scene.load/2`)
    * `:preview` — a live page of the job in a browser (`RingTracer.Preview`):
      `true` (a free port on 127.0.0.1), a port, `[port: p, listen: address]`,
      each printing the page's address on stderr (on the I/O device
      `announce: device` instead, if given) and stopping the page when
      the job ends, or a preview started with `RingTracer.Preview.start/1`
    * `:pixels` — the format of the result's pixels, and of the atoms'
      pixels on their way to the parent: `:float` (default: linear 32-bit
      floats, sent losslessly compressed) or `:srgb8` (8-bit sRGB, a
      quarter of the bytes and fewer still on the wire). PNG files written
      from either are the same bytes; `:srgb8` cannot be written as EXR
      (`RingTracer.Image`). `ringtracer render` picks `:srgb8` when every
      image it writes is a PNG
    * `:ownership` — with `pixels: :srgb8`, also keep the image tinted by
      who traced each atom (the result's `:tinted`), which
      `RingTracer.Report.Ownership` writes (default false; with `:float`
      the map is made from the pixels themselves)

  Returns `{:ok, %RingTracer.Result{}}` or `{:error, %RingTracer.Error{}}`
  for a missing or invalid scene, a bad option, or a job that failed.

  ## Warnings

  A scene that parses but may not render as meant (a zero-radius sphere, a
  colour above 1, an OBJ face whose material is missing; see
  `RingTracer.Scene.Warning`) still renders. Its warnings, each with file and
  line, are returned in the result's `:warnings` (and `:warnings_omitted`
  past the first 100), as they are in `RingTracer.Scene.load/2`'s scene, so
  a caller can show them before rendering or after. This function prints
  and logs nothing (but the address of a preview it starts); `mix ring_tracer.render` prints them to stderr before
  the render starts.
  """
  @spec render(Path.t() | Scene.t(), keyword()) :: {:ok, Result.t()} | {:error, Error.t()}
  def render(scene, opts \\ []) when is_binary(scene) or is_struct(scene, Scene),
    do: render(scene, opts, [])

  # `extra`: fields of the job's spec the public options do not set.
  defp render(scene, opts, extra) do
    with {:ok, opts} <- Options.validate(opts),
         :ok <- running() do
      within(opts[:timeout], fn -> load_and_run(scene, opts, extra) end)
    end
  end

  defp load_and_run(scene, opts, extra) do
    with :ok <- RingTracer.Cluster.connect(Enum.uniq(opts[:nodes])),
         {:ok, scene} <- load(scene, opts),
         :ok <- check_frame(scene, opts[:frame]),
         {:ok, settings} <- settings(scene, opts) do
      :ok = SceneCache.put(scene)

      with {:ok, result} <- run(scene, settings, opts, extra) do
        {:ok, %{result | warnings: scene.warnings, warnings_omitted: scene.warnings_omitted}}
      end
    end
  end

  defp check_frame(%Scene{frames: frames}, frame) when frame <= frames, do: :ok

  defp check_frame(%Scene{frames: frames, source: source}, frame) do
    {:error,
     Error.new(
       :invalid_option,
       "option :frame must be at most #{frames} (the frames of #{source.name}), got: #{frame}"
     )}
  end

  defp load(%Scene{} = scene, _opts), do: {:ok, scene}
  defp load(path, opts), do: Scene.load(path, allow_dirs: opts[:allow_dirs])

  defp running do
    if Process.whereis(RingTracer.Names.jobs()),
      do: :ok,
      else:
        {:error,
         Error.new(
           :not_running,
           "the :ring_tracer application is not running; " <>
             "start it with Application.ensure_all_started(:ring_tracer)"
         )}
  end

  # `:timeout` covers the whole render, the scene's loading included: the
  # work runs in a process of its own, killed at the deadline (the job's
  # parent, which monitors it, then stops every process of the job).
  defp within(:infinity, fun), do: fun.()

  defp within(ms, fun) do
    me = self()
    {pid, ref} = spawn_monitor(fn -> send(me, {__MODULE__, self(), fun.()}) end)

    receive do
      {__MODULE__, ^pid, result} ->
        Process.demonitor(ref, [:flush])
        result

      {:DOWN, ^ref, _, _, reason} ->
        {:error, Error.new(:render_failed, "the render exited: #{inspect(reason)}")}
    after
      ms ->
        Process.exit(pid, :kill)

        receive do
          {:DOWN, ^ref, _, _, _} -> :ok
        end

        receive do
          {__MODULE__, ^pid, _} -> :ok
        after
          0 -> :ok
        end

        {:error, Error.new(:timeout, "timed out after #{ms} ms")}
    end
  end

  @doc "Like `render/2` but returns the result or raises `RingTracer.Error`."
  @spec render!(Path.t(), keyword()) :: Result.t()
  def render!(path, opts \\ []) do
    case render(path, opts) do
      {:ok, result} -> result
      {:error, error} -> raise error
    end
  end

  @doc """
  The settings a render of `scene` with `opts` (already validated) uses.
  """
  @spec settings(Scene.t(), keyword()) :: {:ok, Settings.t()} | {:error, Error.t()}
  def settings(%Scene{} = scene, opts) do
    {width, height} = Scene.image_size(scene, opts[:width], opts[:height])

    settings = %Settings{
      width: width,
      height: height,
      depth: opts[:depth],
      cutoff: opts[:cutoff] / 1,
      samples: opts[:samples],
      spd: opts[:spd],
      region: region(opts[:region], width, height)
    }

    case Native.validate_settings(Settings.to_native(settings)) do
      {:ok, true} -> {:ok, settings}
      {:error, message} -> {:error, Error.new(:invalid_option, message)}
    end
  end

  # `{x0, y0, x1, y1}` in pixels (x1, y1 excluded) or fractions, as
  # `{x0, y0, width, height}` in pixels; the kernel checks it is inside.
  defp region(nil, _w, _h), do: nil

  defp region({x0, y0, x1, y1}, w, h) when is_float(x0) do
    {a, b} = {round(x0 * w), round(y0 * h)}
    {a, b, max(round(x1 * w) - a, 1), max(round(y1 * h) - b, 1)}
  end

  defp region({x0, y0, x1, y1}, _w, _h), do: {x0, y0, x1 - x0, y1 - y0}

  @doc """
  Starts a render and returns at once with a handle. The calling process then
  gets `{RingTracer, id, {:progress, done, total}}` as atoms arrive and
  finally `{RingTracer, id, {:ok, result}}` or `{RingTracer, id, {:error,
  error}}`, where `id` is the handle's `:id`. Same options as `render/2`.

      iex> {:ok, job} = RingTracer.render_async("priv/scenes/tetra_s1.nff", width: 16, height: 16, children: 2, atoms: 2)
      iex> id = job.id
      iex> receive do {RingTracer, ^id, {:ok, result}} -> byte_size(result.pixels) end
      16 * 16 * 12
  """
  @spec render_async(Path.t() | Scene.t(), keyword()) ::
          {:ok, %{id: reference(), pid: pid()}}
  def render_async(path, opts \\ []) when is_binary(path) or is_struct(path, Scene) do
    {:ok,
     start_forwarder(fn progress ->
       render(path, Keyword.put(opts, :progress, progress), announce: true)
     end)}
  end

  # Runs `work` (given the pid progress and frames go to) in a worker, and
  # forwards what the job sends, then the worker's result, to the caller.
  defp start_forwarder(work) do
    caller = self()
    id = make_ref()

    pid =
      spawn(fn ->
        caller_ref = Process.monitor(caller)
        forwarder = self()

        {worker, worker_ref} =
          spawn_monitor(fn -> send(forwarder, {:result, self(), work.(forwarder)}) end)

        forward(%{caller: caller, id: id, caller_ref: caller_ref, worker: {worker, worker_ref}})
      end)

    %{id: id, pid: pid}
  end

  @doc """
  Starts rendering a sequence of frames of an animated scene (see
  docs/scene-format.md, "Animation") through one ring, and returns at once
  with a handle, as `render_async/2` does. The job's processes start once,
  each node parses the scene once, and a child that finishes its part of a
  frame goes on with the next one: the ring does not drain between frames.
  At most `:window` frames are in flight; each frame is byte for byte the
  frame `render/2` gives with `frame: n`.

  The calling process gets `{RingTracer, id, {:frame, n, %RingTracer.Frame{}}}`
  as each frame completes (`n` is its number in the scene, from 1; frames
  complete in about, not exactly, their order), `{RingTracer, id,
  {:progress, done, total}}` as atoms arrive (over every frame), and finally
  `{RingTracer, id, {:ok, %RingTracer.Result{}}}` (the whole sequence's
  statistics, `:pixels` nil, the frames' summaries in `:frames`) or
  `{RingTracer, id, {:error, error}}`. `cancel/1` stops it. See
  `stream_sequence/2` for the frames as a `Stream`.

  ## Options

  Those of `render/2` but `:frame`, `:region` and `:progress` (and the
  ring's `:aim`, which works within one image), and:

    * `:frames` — the scene's frames to render, from 1: a range (`10..20`)
      or an ascending list (default: every frame). A subset keeps the
      whole sequence's clock, as POV-Ray's `+SF`/`+EF` do
    * `:window` — how many frames may be in flight at once (default
      #{RingTracer.Sequence.default_window()}, at most #{RingTracer.Sequence.max_window()})
    * `:ack` — whether a frame stays in the window until the caller
      acknowledges it with `ack_frame/2` (default false): a caller that
      writes frames more slowly than the ring traces them then holds the
      ring back, instead of frames piling up in its mailbox

  Returns `{:error, %RingTracer.Error{}}` at once for a scene or option
  that is not valid.

      iex> {:ok, job} = RingTracer.render_sequence("priv/scenes/whitted_orbit.toml", frames: 1..3, width: 16, height: 12, children: 2, atoms: 2)
      iex> id = job.id
      iex> frames = for _ <- 1..3, do: receive(do: ({RingTracer, ^id, {:frame, n, frame}} -> {n, byte_size(frame.pixels)}))
      iex> Enum.sort(frames)
      [{1, 2304}, {2, 2304}, {3, 2304}]
      iex> receive do {RingTracer, ^id, {:ok, result}} -> length(result.frames) end
      3
  """
  @spec render_sequence(Path.t() | Scene.t(), keyword()) ::
          {:ok, %{id: reference(), pid: pid()}} | {:error, Error.t()}
  def render_sequence(scene, opts \\ []) when is_binary(scene) or is_struct(scene, Scene) do
    {sequence, opts} = Keyword.split(opts, [:frames, :window, :ack])

    with :ok <- not_for_sequences(opts),
         {:ok, opts} <- Options.validate(opts),
         :ok <- running(),
         :ok <- RingTracer.Cluster.connect(Enum.uniq(opts[:nodes])),
         {:ok, scene} <- load(scene, opts),
         {:ok, frames, window, ack} <-
           RingTracer.Sequence.options(sequence, scene.frames, scene.source.name),
         {:ok, settings} <- settings(scene, opts),
         {:ok, _strategy} <- strategy(settings, opts, length(frames)) do
      :ok = SceneCache.put(scene)
      extra = [frames: frames, window: window, sequence: true, ack: ack, announce: true]

      {:ok,
       start_forwarder(fn progress ->
         opts = Keyword.put(opts, :progress, progress)

         within(opts[:timeout], fn ->
           with {:ok, result} <- run(scene, settings, opts, extra) do
             {:ok, %{result | warnings: scene.warnings, warnings_omitted: scene.warnings_omitted}}
           end
         end)
       end)}
    end
  end

  defp not_for_sequences(opts) do
    case Enum.find([:frame, :region, :progress], &Keyword.has_key?(opts, &1)) do
      nil ->
        :ok

      key ->
        {:error, Error.new(:invalid_option, "option #{inspect(key)} is not one of a sequence's")}
    end
  end

  @doc """
  Tells a sequence started with `ack: true` (`render_sequence/2`) that the
  caller is done with frame `number` (for instance, has written it), so
  that it leaves the window. Returns `:ok`; a number not sent yet, or
  acknowledged already, is ignored.
  """
  @spec ack_frame(%{:pid => pid(), optional(atom()) => term()}, pos_integer()) :: :ok
  def ack_frame(%{pid: pid}, number) when is_integer(number) do
    send(pid, {:ack, number})
    :ok
  end

  @doc """
  A sequence's frames as a `Stream` of `RingTracer.Frame`s, in the order
  they complete: the sequence starts when the stream is run
  (`render_sequence/2`, with its options, and `ack: true`: a frame leaves
  the window once the stream's consumer asks for the next one, so a slow
  consumer holds the ring back) and is cancelled if the stream is halted
  early. An error (an invalid option, a job that failed) raises
  `RingTracer.Error`.

      iex> RingTracer.stream_sequence("priv/scenes/whitted_orbit.toml", frames: [2, 5], width: 8, height: 6, children: 2)
      ...> |> Enum.map(& &1.number) |> Enum.sort()
      [2, 5]
  """
  @spec stream_sequence(Path.t() | Scene.t(), keyword()) :: Enumerable.t()
  def stream_sequence(scene, opts \\ []) do
    Stream.resource(
      fn ->
        case render_sequence(scene, Keyword.put(opts, :ack, true)) do
          {:ok, job} -> {job, nil}
          {:error, error} -> raise error
        end
      end,
      fn
        nil ->
          {:halt, nil}

        {%{id: id} = job, last} ->
          if last, do: ack_frame(job, last)

          receive do
            {RingTracer, ^id, {:frame, n, frame}} -> {[frame], {job, n}}
            {RingTracer, ^id, {:progress, _, _}} -> {[], {job, nil}}
            {RingTracer, ^id, {:ok, _result}} -> {:halt, nil}
            {RingTracer, ^id, {:error, error}} -> raise error
          end
      end,
      fn
        nil -> :ok
        {job, _} -> cancel(job)
      end
    )
  end

  # Exactly one final message reaches the caller: the result, an error if
  # the render crashed, or `:cancelled` after `cancel/1`.
  defp forward(%{caller: caller, id: id, worker: {worker, worker_ref}} = f) do
    receive do
      {RingTracer, _, {:progress, _, _} = progress} ->
        send(caller, {RingTracer, id, progress})
        forward(f)

      {RingTracer, _, {:frame, _, _} = frame} ->
        send(caller, {RingTracer, id, frame})
        forward(f)

      {RingTracer, _, {:parent, parent}} ->
        for request <- Enum.reverse(Map.get(f, :requests, [])), do: send(parent, request)
        forward(f |> Map.put(:parent, parent) |> Map.delete(:requests))

      # `grow/4`, `shrink/3`: to the parent, once it is known.
      {:job_request, request} ->
        case f do
          %{parent: parent} ->
            send(parent, request)
            forward(f)

          _ ->
            forward(Map.update(f, :requests, [request], &[request | &1]))
        end

      {:ack, number} ->
        if parent = f[:parent], do: send(parent, {:frame_ack, number})
        forward(f)

      {:result, ^worker, result} ->
        send(caller, {RingTracer, id, result})

      {:DOWN, ^worker_ref, _, _, reason} ->
        message = "the render exited: #{inspect(reason)}"
        send(caller, {RingTracer, id, {:error, Error.new(:render_failed, message)}})

      {:cancel, from, ref} ->
        stop_worker(f)

        send(
          caller,
          {RingTracer, id, {:error, Error.new(:cancelled, "the render was cancelled")}}
        )

        send(from, {:cancelled, ref})

      {:DOWN, ref, _, _, _} when ref == f.caller_ref ->
        stop_worker(f)
    end
  end

  defp stop_worker(%{worker: {worker, ref}}) do
    Process.exit(worker, :kill)

    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    end
  end

  @doc """
  Adds `count` children on `node` to a running job (a handle of
  `render_async/2` or `render_sequence/2`): the ring gains members. `node`
  is this node or a connected node that runs `:ring_tracer`; the scene is
  shipped there if the job has not used it yet. The new children hold no
  atoms at first and find work through the job's strategy, as an idle
  child does (the ring: help offers; steal: steals; master: the parent's
  next atoms; static: none in this frame); in a sequence, later frames are
  cut over every child. The image is the same, byte for byte. Returns the
  new children's indices (after the job's first `:children`).

  ## Options

    * `:timeout` — milliseconds to wait for the job's answer (default
      #{@job_call_timeout}); past it, `{:error, %RingTracer.Error{reason: :timeout}}`, and
      the children may still join

  Errors: `:job_ended` (the job is over, or ends before it answers),
  `:invalid_option` (a count that is not a positive integer, more
  children than a job may have, a bad option), `:node_unavailable` (a node
  that cannot be reached, does not run the application, or could not
  start the children).
  """
  @spec grow(%{:pid => pid(), optional(atom()) => term()}, node(), pos_integer(), keyword()) ::
          {:ok, [non_neg_integer()]} | {:error, Error.t()}
  def grow(%{pid: pid} = _handle, node, count, opts \\ []) when is_pid(pid) do
    with {:ok, timeout} <- job_call_timeout(opts),
         :ok <- check_count(count),
         :ok <- check_node(node),
         :ok <- RingTracer.Cluster.check([node]) do
      job_call(pid, timeout, fn ref -> {:grow, ref, node, count} end)
    end
  end

  @doc """
  The children of a running job (a handle of `render_async/2` or
  `render_sequence/2`) on `node` leave its ring: each stops, and the atoms
  it had not traced are handed to the others, as a lost child's are (its
  statistics stay in the result, and it is no failure). The image is the
  same. Returns the indices of the children that leave (none when the job
  has none on `node`). A job whose every child leaves fails, as one that
  lost every child does.

  ## Options

    * `:timeout` — milliseconds to wait for the job's answer (default
      #{@job_call_timeout})

  Errors: `:job_ended`, `:invalid_option`, `:timeout`.
  """
  @spec shrink(%{:pid => pid(), optional(atom()) => term()}, node(), keyword()) ::
          {:ok, [non_neg_integer()]} | {:error, Error.t()}
  def shrink(%{pid: pid} = _handle, node, opts \\ []) when is_pid(pid) do
    with {:ok, timeout} <- job_call_timeout(opts),
         :ok <- check_node(node) do
      job_call(pid, timeout, fn ref -> {:shrink, ref, node} end)
    end
  end

  defp job_call_timeout(opts) do
    case Keyword.get(opts, :timeout, @job_call_timeout) do
      t when (is_integer(t) and t > 0) or t == :infinity ->
        {:ok, t}

      t ->
        {:error,
         Error.new(
           :invalid_option,
           "option :timeout must be a positive integer or :infinity, got: #{inspect(t)}"
         )}
    end
  end

  defp check_count(count) when is_integer(count) and count > 0, do: :ok

  defp check_count(count),
    do:
      {:error,
       Error.new(:invalid_option, "count must be a positive integer, got: #{inspect(count)}")}

  defp check_node(node) when is_atom(node) and node not in [nil, true, false], do: :ok

  defp check_node(node),
    do: {:error, Error.new(:invalid_option, "node must be a node name, got: #{inspect(node)}")}

  # A request to a job's parent, through its forwarder (which holds it until
  # the parent is known). The reply comes to an alias of the monitor on the
  # forwarder: once the call is over, a late reply is dropped.
  defp job_call(forwarder, timeout, request) do
    ref = :erlang.monitor(:process, forwarder, [{:alias, :demonitor}])
    send(forwarder, {:job_request, request.(ref)})

    receive do
      {^ref, reply} ->
        Process.demonitor(ref, [:flush])
        job_reply(reply)

      {:DOWN, ^ref, _, _, _} ->
        job_reply({:error, :job_ended})
    after
      timeout ->
        Process.demonitor(ref, [:flush])
        {:error, Error.new(:timeout, "the job did not answer within #{timeout} ms")}
    end
  end

  defp job_reply({:ok, indices}), do: {:ok, indices}
  defp job_reply({:error, :job_ended}), do: {:error, Error.new(:job_ended, "the job has ended")}
  defp job_reply({:error, {reason, message}}), do: {:error, Error.new(reason, message)}

  @doc """
  Cancels a render started with `render_async/2`: the job's parent, children
  and grandchildren stop, and the caller of `render_async/2` gets `{RingTracer,
  id, {:error, %RingTracer.Error{reason: :cancelled}}}` as its final message
  (unless the render had finished: then its result was the final message).
  Returns `:ok`.
  """
  @spec cancel(%{:pid => pid(), optional(atom()) => term()}) :: :ok
  def cancel(%{pid: pid}) do
    ref = Process.monitor(pid)
    send(pid, {:cancel, self(), ref})

    receive do
      {:DOWN, ^ref, _, _, _} ->
        receive do
          {:cancelled, ^ref} -> :ok
        after
          0 -> :ok
        end
    end
  end

  @doc """
  Runs the same parent, children and strategies on the simulated kernel
  (`RingTracer.Kernel.Simulated`): each atom sleeps for its cost instead of
  being traced, so rings of hundreds or thousands of children fit on one
  machine. The image is black; the statistics are what matters.

  ## Options

  Those of `render/2` that concern the job (`:children`, `:atoms`,
  `:strategy`, `:layout`, `:speeds`, `:timeout`), and `:costs`: per-atom costs in
  microseconds (see `RingTracer.Kernel.Simulated`; default
  #{RingTracer.Kernel.Simulated.default_cost()} each).

      iex> {:ok, result} = RingTracer.simulate(children: 16, atoms: 4, costs: 1000)
      iex> length(result.atoms)
      64
  """
  @spec simulate(keyword()) :: {:ok, Result.t()} | {:error, Error.t()}
  def simulate(opts \\ []) do
    {costs, opts} = Keyword.pop(opts, :costs, RingTracer.Kernel.Simulated.default_cost())

    with {:ok, opts} <- Options.validate(opts),
         :ok <- running() do
      n = opts[:children] * opts[:atoms]
      settings = %Settings{width: n, height: 1}
      source = RingTracer.Scene.Source.new("simulated", "sim", "", %{})
      kernel = {RingTracer.Kernel.Simulated, costs: RingTracer.Kernel.Simulated.pack(costs)}
      within(opts[:timeout], fn -> run(source, settings, kernel, :infinity, opts) end)
    end
  end

  defp run(%Scene{} = scene, settings, opts, extra) do
    run(
      scene.source,
      settings,
      opts[:kernel] || {RingTracer.Kernel.Native, []},
      :erlang.system_info(:dirty_cpu_schedulers_online),
      opts,
      extra
    )
  end

  defp run(source, settings, kernel, capacity_cap, opts, extra \\ []) do
    frames = Keyword.get(extra, :frames, [opts[:frame] - 1])

    with {:ok, strategy} <- strategy(settings, opts, length(frames)) do
      spec = %Spec{
        id: make_ref(),
        source: source,
        settings: settings,
        layout: layout(settings, opts, length(frames)),
        caller: self(),
        nodes: opts[:nodes],
        liveness: opts[:liveness],
        strategy: strategy,
        kernel: kernel,
        speeds: opts[:speeds],
        progress: opts[:progress],
        frames: frames,
        pixels: opts[:pixels],
        tint: opts[:ownership] and opts[:pixels] == :srgb8
      }

      spec = struct!(spec, extra)
      # a sequence has no ownership map
      spec = %{spec | tint: spec.tint and not spec.sequence}

      preview = RingTracer.Preview.for_job(opts[:preview], spec.id, opts[:nodes])
      {:ok, parent} = Parent.start(spec)
      ref = Process.monitor(parent)
      RingTracer.Preview.watch_job(preview, parent)
      result = await(spec, settings, capacity_cap, ref, opts)
      RingTracer.Preview.after_job(preview)
      result
    end
  end

  defp layout(settings, opts, frames) do
    {width, height} = Settings.traced_size(settings)

    Layout.new(width, height, opts[:children], opts[:atoms], opts[:layout])
    |> Layout.with_frames(frames)
  end

  # The job's strategy, `{module, options}`, its options checked by the
  # strategy itself for the job's layout.
  defp strategy(settings, opts, frames),
    do: RingTracer.Strategies.resolve(opts[:strategy], layout(settings, opts, frames))

  defp await(spec, settings, capacity_cap, ref, opts) do
    receive do
      {RingTracer, id, reply} when id == spec.id ->
        receive do
          {:DOWN, ^ref, _, _, _} -> :ok
        end

        case reply do
          {:ok, raw} ->
            {_module, strategy_options} = spec.strategy
            name = RingTracer.Strategies.name(opts[:strategy])
            {:ok, Result.new(settings, {name, strategy_options}, capacity_cap, raw)}

          {:error, {reason, message}} ->
            {:error, Error.new(reason, message)}

          {:error, message} ->
            {:error, Error.new(:render_failed, message)}
        end

      {:DOWN, ^ref, _, _, reason} ->
        {:error, Error.new(:render_failed, "the job's parent exited: #{inspect(reason)}")}
    end
  end
end
