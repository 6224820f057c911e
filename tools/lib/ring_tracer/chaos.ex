defmodule RingTracer.Chaos do
  @moduledoc false
  # A chaos soak: many concurrent jobs of several scenes across peer nodes on
  # this machine, with grandchildren, children and whole nodes killed and
  # nodes frozen at random moments, every image checked against a clean
  # render. `mix ring_tracer.chaos` runs it and prints `format/1`.
  #
  # What happens is a pure function of the seed (`RingTracer.Chaos.Plan`):
  # each job's scene, strategy, ring size, atoms, slowdowns, and its faults,
  # each due at an atom count. A job's driver starts it with
  # `RingTracer.render_async/2` on this node and the peer nodes that are up
  # (`RingTracer.Chaos.Pool`), and when the parent has reported that many
  # atoms it injects the fault from outside the job, as an operator or a
  # failing machine would; nothing in the render path knows about the soak:
  #
  #   * the job's parent is the child of `RingTracer.Jobs` that monitors the
  #     render's caller; its children are the `:children` of its state
  #     (`:sys.get_state/2`), which holds the living ones only;
  #   * a grandchild is the process its child is linked to besides the
  #     node's `RingTracer.Children` supervisor;
  #   * processes die by `Process.exit(pid, :kill)`, nodes by SIGKILL of
  #     their OS process, and a frozen node gets SIGSTOP, then SIGCONT after
  #     `:freeze` ms (longer than the jobs' `:liveness`, so that they must
  #     declare it dead). Killed and frozen nodes are replaced.
  #
  # Victims are drawn by the plan's pick among the candidates alive when the
  # fault is due (children by index, nodes by name). The soak never takes
  # the last living child on this node, so no job loses every child, nor a
  # third grandchild of one child in one job (a child gives up on an atom
  # after three failed attempts, by design). A fault with no candidate, or
  # due after its job ended, is skipped and counted as such.
  #
  # ## What is checked, per job
  #
  #   * **atoms lost** — atoms of the job whose pixels the caller did not
  #     get: for a job that failed or hung, the atoms its parent never
  #     received (the job's atom count minus its last progress count); a
  #     completed job loses none, since its parent holds every atom before
  #     it replies.
  #   * **atoms traced twice** — atom results that reached the parent after
  #     the atom's first one (`result.duplicates`, of which the parent keeps
  #     the first) that no loss explains. After a child or node is lost the
  #     parent hands out again the atoms that never arrived
  #     (`result.redone`); one of those may arrive twice, once from a tracer
  #     whose result was still on its way, and that is allowed (reported
  #     apart as *re-traced after a loss*). So a job counts `max(duplicates -
  #     redone, 0)`; a job that lost no child counts `max(duplicates, traced
  #     - atoms)`, where `traced` sums the children's own counts of atoms
  #     traced and sent, so the children and the parent are checked against
  #     each other.
  #   * **images differing** — completed jobs whose pixels are not
  #     byte-for-byte the scene's clean render (this node only, no faults,
  #     computed once per scene and checked against the kernel's own
  #     whole-image render); for each, the atoms whose pixels differ.
  #   * **messages per atom** — `RingTracer.Result.per_atom/1` of each
  #     completed job (for a sequence, its messages over all its frames'
  #     atoms); the report has the median and the worst.
  #
  # ## What is checked, per sequence
  #
  # A sequence job (`RingTracer.render_sequence/2`, a share of the jobs set
  # by `:sequences`) renders a few frames of an animated scene through one
  # ring, and meets the same faults, due at atom counts over all its frames.
  # Its atoms are checked as an image's are (lost, traced twice, messages
  # per atom; its progress and its children's counts cover every frame),
  # and its frames as they arrive:
  #
  #   * **frames lost** — frames asked for that never came (a completed job
  #     loses none);
  #   * **frames twice** — deliveries of a frame number already delivered
  #     (the caller would write that frame twice): there must be none;
  #   * **frames differing** — frames that are not byte-for-byte that frame's
  #     clean render (this node only, no faults, computed once per frame and
  #     checked against the kernel's own whole-image render of that frame),
  #     with the atoms whose pixels differ; a frame not asked for counts as
  #     differing.

  alias RingTracer.Chaos.{Plan, Pool}
  alias RingTracer.{Layout, Native, Result, Scene, Settings}

  @default_scenes ~w(balls_s2.nff tetra_s3.nff whitted.toml spd/teapot_s6.nff)
  @default_sequence_scene "whitted_orbit.toml"

  @typedoc "One job's outcome and figures."
  @type outcome :: %{
          job: Plan.job(),
          status: :ok | :failed | :hung,
          error: String.t() | nil,
          faults: [map()],
          atoms: pos_integer(),
          lost: non_neg_integer(),
          twice: non_neg_integer(),
          retraced: non_neg_integer(),
          differs: boolean(),
          atoms_differing: non_neg_integer(),
          frames: non_neg_integer(),
          frames_lost: non_neg_integer(),
          frames_twice: non_neg_integer(),
          frames_differing: non_neg_integer(),
          messages_per_atom: float() | nil,
          messages: %{atom() => non_neg_integer()},
          children_lost: non_neg_integer(),
          grandchild_restarts: non_neg_integer(),
          redone: non_neg_integer(),
          elapsed_ms: non_neg_integer()
        }

  @typedoc """
  What `run/2` returns: the options used, every job's outcome, the pool's
  figures, and the parents and children still alive on this node 5 s after
  the last job ended (none should be: no process of a job outlives it).
  """
  @type report :: %{
          options: keyword(),
          outcomes: [outcome()],
          pool: Pool.stats(),
          left_behind: non_neg_integer(),
          elapsed_ms: non_neg_integer()
        }

  @doc "The scenes the soak renders unless told otherwise (names under `priv/scenes`)."
  @spec default_scenes() :: [String.t()]
  def default_scenes, do: @default_scenes

  @doc """
  The options and their defaults.

    * `:seed` (1), `:jobs` (100), `:faults_per_job` (2), `:weights`
      (`RingTracer.Chaos.Plan.default_weights/0`), `:strategies`
      (`[:ring]`), `:children` (`3..6`), `:atoms` (`4..8`), `:slowdown`
      (`300..1000`) — the plan's, see `RingTracer.Chaos.Plan.new/1`;
    * `:scenes` — file names under `priv/scenes`, or paths
      (`default_scenes/0`);
    * `:sequences` — the percentage of jobs that are sequences (20);
      `:sequence_scene` — their animated scene, a name under `priv/scenes`
      or a path (`#{@default_sequence_scene}`, 48 frames); `:frames` — how
      many of its frames a sequence renders (`2..4`), drawn among all of
      them; `:window` — a sequence's window (`1..3`);
    * `:concurrency` — jobs at once (3);
    * `:nodes` — peer nodes (3);
    * `:width`, `:height` — the image size of every job (96 x 72);
    * `:liveness` — the jobs' liveness timeout in ms (1500);
    * `:freeze` — how long a frozen node stays stopped, in ms (twice
      `:liveness`);
    * `:timeout` — ms after which a job counts as hung and is cancelled
      (60,000);
    * `:only` — run only these job indexes of the plan (default all), to
      reproduce one job of a soak;
    * `:log_level` — the peer nodes' logger level (`:error`: nodes drop on
      purpose, and every peer would log it).
  """
  @spec defaults() :: keyword()
  def defaults do
    [
      seed: 1,
      jobs: 100,
      faults_per_job: 2,
      weights: Plan.default_weights(),
      strategies: [:ring],
      children: 3..6,
      atoms: 4..8,
      slowdown: 300..1000,
      scenes: @default_scenes,
      sequences: 20,
      sequence_scene: @default_sequence_scene,
      frames: 2..4,
      window: 1..3,
      concurrency: 3,
      nodes: 3,
      width: 96,
      height: 72,
      liveness: 1500,
      freeze: nil,
      timeout: 60_000,
      only: nil,
      log_level: :error
    ]
  end

  @doc """
  Runs the soak (see `defaults/0` for `opts`) and returns its report. The
  application must be running; this node is made distributed if it is not.
  `progress`, if given, is called with each job's outcome as it ends.
  """
  @spec run(keyword(), (outcome() -> term()) | nil) :: report()
  def run(opts \\ [], progress \\ nil) do
    opts = Keyword.merge(defaults(), opts)
    opts = Keyword.put(opts, :freeze, opts[:freeze] || 2 * opts[:liveness])
    t0 = System.monotonic_time(:millisecond)
    check_options(opts)
    sequence = sequence_scene(opts)
    paths = Map.new(opts[:scenes], &{&1, scene_path(&1)})
    references = Map.new(paths, fn {name, path} -> {name, reference(path, opts)} end)

    plan =
      opts
      |> Keyword.take([
        :seed,
        :jobs,
        :scenes,
        :strategies,
        :children,
        :atoms,
        :slowdown,
        :faults_per_job,
        :weights,
        :sequences,
        :sequence_scene,
        :frames,
        :window
      ])
      |> Keyword.put(:scene_frames, sequence && sequence.scene.frames)
      |> Plan.new()
      |> Enum.filter(&(opts[:only] == nil or &1.index in opts[:only]))

    # Each frame any sequence asks for, rendered clean once.
    frame_references =
      plan
      |> Enum.flat_map(&(&1.frames || []))
      |> Enum.uniq()
      |> Map.new(&{&1, frame_reference(sequence, &1, opts)})

    {:ok, pool} = Pool.start_link(opts[:nodes], log_level: opts[:log_level])

    try do
      ctx = %{
        pool: pool,
        paths: paths,
        references: references,
        sequence_path: sequence && sequence.path,
        frame_references: frame_references,
        opts: opts
      }

      outcomes =
        plan
        |> Task.async_stream(
          fn job ->
            outcome = run_job(job, ctx)
            if progress, do: progress.(outcome)
            outcome
          end,
          max_concurrency: opts[:concurrency],
          timeout: :infinity,
          ordered: true
        )
        |> Enum.map(fn {:ok, outcome} -> outcome end)

      %{
        options: opts,
        outcomes: outcomes,
        pool: Pool.stats(pool),
        left_behind: left_behind(),
        elapsed_ms: System.monotonic_time(:millisecond) - t0
      }
    after
      Pool.stop(pool)
    end
  end

  # Parents and children of any job still alive on this node, once they
  # have had 5 s to go.
  defp left_behind(tries \\ 50) do
    n =
      Enum.sum(
        for sup <- [RingTracer.Jobs, RingTracer.Children],
            do: DynamicSupervisor.count_children(sup).active
      )

    if n == 0 or tries == 0 do
      n
    else
      Process.sleep(100)
      left_behind(tries - 1)
    end
  end

  # The largest job the plan can draw must be one render/2 accepts, or
  # every job would fail on its options.
  defp check_options(opts) do
    job = [
      children: opts[:children].last,
      atoms: opts[:atoms].last,
      speeds: [opts[:slowdown].first, opts[:slowdown].last],
      width: opts[:width],
      height: opts[:height],
      liveness: opts[:liveness]
    ]

    case RingTracer.Options.validate(job) do
      {:ok, _} -> :ok
      {:error, error} -> raise ArgumentError, "chaos soak: " <> Exception.message(error)
    end

    unless opts[:sequences] in 0..100,
      do: raise(ArgumentError, "chaos soak: :sequences must be a percentage from 0 to 100")
  end

  # The sequences' scene, loaded (for its frame count and clean renders);
  # nil without sequences. Its frames and the largest window asked must be
  # ones render_sequence/2 accepts.
  defp sequence_scene(opts) do
    if opts[:sequences] > 0 do
      name = opts[:sequence_scene]
      path = scene_path(name)

      scene =
        case Scene.load(path) do
          {:ok, scene} -> scene
          {:error, error} -> raise ArgumentError, "chaos soak: " <> Exception.message(error)
        end

      if opts[:frames].first > scene.frames,
        do:
          raise(
            ArgumentError,
            "chaos soak: sequences of at least #{opts[:frames].first} frames asked, " <>
              "but #{name} has #{scene.frames}"
          )

      case RingTracer.Sequence.options([window: opts[:window].last], scene.frames, name) do
        {:ok, _frames, _window, _ack} -> :ok
        {:error, error} -> raise ArgumentError, "chaos soak: " <> Exception.message(error)
      end

      %{path: path, scene: scene}
    end
  end

  @doc """
  A scene name under `priv/scenes`, or a path to a scene file, as an
  absolute path; raises for a missing file.
  """
  @spec scene_path(String.t()) :: Path.t()
  def scene_path(name) do
    priv = Path.join(:code.priv_dir(:ring_tracer) |> List.to_string(), "scenes")

    path =
      Enum.find([name, Path.join(priv, name)], &File.regular?/1) ||
        raise ArgumentError, "no scene #{name} (neither a file nor in #{priv})"

    Path.expand(path)
  end

  # The clean render: this node only, no faults; it must be the kernel's
  # own whole-image render, or the ground truth itself is wrong.
  defp reference(path, opts) do
    {:ok, result} = RingTracer.render(path, width: opts[:width], height: opts[:height])
    scene = Scene.load!(path)
    settings = %Settings{width: opts[:width], height: opts[:height]}
    {:ok, {pixels, _rays}} = Native.render_image(scene.ref, Settings.to_native(settings), 1)

    if pixels != result.pixels,
      do: raise("the clean render of #{path} differs from the kernel's own whole-image render")

    pixels
  end

  # A frame's clean render, likewise checked against the kernel's own
  # whole-image render of that frame.
  defp frame_reference(%{path: path, scene: scene}, n, opts) do
    {:ok, result} = RingTracer.render(path, frame: n, width: opts[:width], height: opts[:height])

    {:ok, ref} = Native.scene_frame(scene.ref, n - 1)
    settings = %Settings{width: opts[:width], height: opts[:height]}
    {:ok, {pixels, _rays}} = Native.render_image(ref, Settings.to_native(settings), 1)

    if pixels != result.pixels,
      do: raise("the clean render of frame #{n} of #{path} differs from the kernel's own")

    pixels
  end

  ## One job

  defp run_job(job, ctx) do
    opts = ctx.opts
    {ref, nodes} = Pool.checkout(ctx.pool)
    t0 = System.monotonic_time(:millisecond)

    st = %{
      job: job,
      ctx: ctx,
      ref: ref,
      handle: nil,
      parent: nil,
      due: job.faults,
      done: 0,
      faults: [],
      gc_kills: %{},
      killed: MapSet.new(),
      frames: %{},
      frames_differing: MapSet.new(),
      frame_atoms_differing: 0,
      deadline: t0 + opts[:timeout]
    }

    {st, final} =
      case start(job, nodes, ctx) do
        {:ok, handle} -> await(%{st | handle: handle})
        {:error, error} -> {st, {:error, error}}
      end

    Pool.started(ctx.pool, ref)
    skipped = Enum.map(st.due, &Map.put(&1, :result, {:skipped, "the job had ended"}))
    st = %{st | faults: Enum.reverse(st.faults) ++ skipped}
    outcome(st, final, System.monotonic_time(:millisecond) - t0)
  end

  defp start(job, nodes, ctx) do
    opts = [
      children: job.children,
      atoms: job.atoms,
      width: ctx.opts[:width],
      height: ctx.opts[:height],
      strategy: job.strategy,
      speeds: job.speeds,
      nodes: nodes,
      liveness: ctx.opts[:liveness]
    ]

    if job.frames,
      do:
        RingTracer.render_sequence(
          ctx.sequence_path,
          opts ++ [frames: job.frames, window: job.window]
        ),
      else: RingTracer.render_async(ctx.paths[job.scene], opts)
  end

  defp await(%{handle: %{id: id}} = st) do
    left = max(st.deadline - System.monotonic_time(:millisecond), 0)

    receive do
      {RingTracer, ^id, {:progress, done, _total}} ->
        st = if st.parent == nil, do: running(st), else: st
        st = %{st | done: max(done, st.done)}
        {now, later} = Enum.split_while(st.due, &(&1.at <= st.done))
        await(Enum.reduce(now, %{st | due: later}, &inject/2))

      {RingTracer, ^id, {:frame, n, %RingTracer.Frame{} = frame}} ->
        await(frame(st, n, frame))

      {RingTracer, ^id, final} ->
        {st, final}
    after
      left -> {cancel(st), :hung}
    end
  end

  # A sequence's frame: counted by its number (a number twice is a frame
  # written twice) and checked against that frame's clean render at once,
  # so that no frame's pixels are kept. A frame not asked for has none.
  defp frame(st, n, frame) do
    st = %{st | frames: Map.update(st.frames, n, 1, &(&1 + 1))}
    reference = Map.get(st.ctx.frame_references, n)

    cond do
      n in (st.job.frames || []) and frame.pixels == reference ->
        st

      MapSet.member?(st.frames_differing, n) ->
        st

      true ->
        atoms =
          if reference,
            do: atoms_differing(frame.pixels, reference, st.job, {frame.width, frame.height}),
            else: 0

        %{
          st
          | frames_differing: MapSet.put(st.frames_differing, n),
            frame_atoms_differing: st.frame_atoms_differing + atoms
        }
    end
  end

  # No result in time: the job is cancelled, and its last messages dropped.
  defp cancel(%{handle: handle} = st) do
    :ok = RingTracer.cancel(handle)
    drain(handle.id)
    st
  end

  defp drain(id) do
    receive do
      {RingTracer, ^id, _} -> drain(id)
    after
      0 -> :ok
    end
  end

  # The first atom is in: the parent's ring runs, node faults may land.
  defp running(st) do
    Pool.started(st.ctx.pool, st.ref)
    %{st | parent: find_parent(st.handle.pid)}
  end

  # `render_async/2`'s forwarder monitors the process that calls render/2
  # (and its own caller); the job's parent monitors that process too.
  defp find_parent(forwarder) do
    parents = for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Jobs), do: pid

    case Process.info(forwarder, :monitors) do
      {:monitors, monitors} ->
        Enum.find_value(monitors, fn
          {:process, pid} when is_pid(pid) and node(pid) == node() ->
            case Process.info(pid, :monitored_by) do
              {:monitored_by, watchers} -> Enum.find(parents, &(&1 in watchers))
              nil -> nil
            end

          _ ->
            nil
        end)

      nil ->
        nil
    end
  end

  defp inject(fault, st) do
    {result, st} =
      try do
        inject(fault.kind, fault.pick, st)
      catch
        kind, reason -> {{:skipped, "#{kind}: #{inspect(reason)}"}, st}
      end

    %{st | faults: [Map.put(fault, :result, result) | st.faults]}
  end

  # Candidates are the living children on this node and on peers that are
  # up: a process on a node that is frozen or going is out of reach anyway.
  defp inject(kind, pick, st) do
    case live_children(st.parent) do
      {:ok, children} ->
        usable = [node() | Pool.up(st.ctx.pool)]

        children =
          Enum.filter(children, fn {_, pid} ->
            node(pid) in usable and not MapSet.member?(st.killed, pid)
          end)

        inject(kind, pick, children, st)

      {:error, why} ->
        {{:skipped, why}, st}
    end
  end

  defp inject(:grandchild, pick, children, st) do
    candidates = Enum.filter(children, fn {i, _} -> Map.get(st.gc_kills, i, 0) < 2 end)

    with {:ok, {i, child}} <- choose(candidates, pick, "no child whose grandchild may die"),
         gc when is_pid(gc) <- grandchild(child),
         false <- MapSet.member?(st.killed, gc) do
      Process.exit(gc, :kill)
      {{:injected, "grandchild of child #{i} on #{node(child)}"}, killed(bump_gc(st, i), gc)}
    else
      {:skipped, _} = skipped -> {skipped, st}
      nil -> {{:skipped, "the child had no grandchild"}, st}
      true -> {{:skipped, "its grandchild was killed already and not yet restarted"}, st}
    end
  end

  defp inject(:child, pick, children, st) do
    local = Enum.filter(children, fn {_, pid} -> node(pid) == node() end)
    candidates = if length(local) > 1, do: children, else: children -- local

    case choose(candidates, pick, "no child but the last on this node") do
      {:ok, {i, child}} ->
        Process.exit(child, :kill)
        {{:injected, "child #{i} on #{node(child)}"}, killed(st, child)}

      skipped ->
        {skipped, st}
    end
  end

  defp inject(kind, pick, children, st) when kind in [:node, :freeze] do
    nodes =
      children
      |> Enum.map(fn {_, pid} -> node(pid) end)
      |> Enum.reject(&(&1 == node()))
      |> Enum.uniq()
      |> Enum.sort()

    with {:ok, target} <- choose(nodes, pick, "no child on another node") do
      result =
        if kind == :node,
          do: Pool.kill(st.ctx.pool, target),
          else: Pool.freeze(st.ctx.pool, target, st.ctx.opts[:freeze])

      case result do
        :ok -> {{:injected, "#{target}"}, st}
        skipped -> {skipped, st}
      end
    else
      skipped -> {skipped, st}
    end
  end

  defp killed(st, pid), do: %{st | killed: MapSet.put(st.killed, pid)}

  defp bump_gc(st, i), do: %{st | gc_kills: Map.update(st.gc_kills, i, 1, &(&1 + 1))}

  defp choose([], _pick, why), do: {:skipped, why}
  defp choose(list, pick, _why), do: {:ok, Enum.at(list, rem(pick, length(list)))}

  # The parent's living children, by index.
  defp live_children(nil), do: {:error, "the job's parent was not found"}

  defp live_children(parent) do
    case :sys.get_state(parent, 2_000) do
      %{children: children} when is_map(children) -> {:ok, Enum.sort(children)}
      _ -> {:error, "the parent's state has no :children"}
    end
  catch
    :exit, _ -> {:error, "the job's parent had ended"}
  end

  defp grandchild(child) do
    if node(child) == node(),
      do: grandchild_of(child),
      else: :erpc.call(node(child), __MODULE__, :grandchild_of, [child], 2_000)
  end

  @doc false
  # Run on the child's node: the process a child is linked to besides the
  # node's children supervisor is its grandchild.
  @spec grandchild_of(pid()) :: pid() | nil
  def grandchild_of(child) do
    sup = Process.whereis(RingTracer.Names.children())

    case Process.info(child, :links) do
      {:links, links} -> Enum.find(links, &(is_pid(&1) and &1 != sup))
      nil -> nil
    end
  end

  ## Figures

  defp outcome(st, final, elapsed_ms) do
    job = st.job
    total = total_atoms(job)
    asked = job.frames || []

    base = %{
      job: job,
      status: :ok,
      error: nil,
      faults: st.faults,
      atoms: total,
      lost: 0,
      twice: 0,
      retraced: 0,
      differs: false,
      atoms_differing: st.frame_atoms_differing,
      frames: length(asked),
      frames_lost: Enum.count(asked, &(not Map.has_key?(st.frames, &1))),
      frames_twice: st.frames |> Map.values() |> Enum.map(&(&1 - 1)) |> Enum.sum(),
      frames_differing: MapSet.size(st.frames_differing),
      messages_per_atom: nil,
      messages: %{},
      children_lost: 0,
      grandchild_restarts: 0,
      redone: 0,
      elapsed_ms: elapsed_ms
    }

    case final do
      {:ok, %Result{} = result} ->
        Map.merge(base, figures(result, st.ctx.references[job.scene], job))

      {:error, error} ->
        %{base | status: :failed, error: Exception.message(error), lost: total - st.done}

      :hung ->
        %{
          base
          | status: :hung,
            error: "no result after #{st.ctx.opts[:timeout]} ms",
            lost: total - st.done
        }
    end
  end

  # A job's atoms: every frame's, for a sequence.
  defp total_atoms(job), do: job.children * job.atoms * length(job.frames || [1])

  defp figures(result, reference, job) do
    total = total_atoms(job)
    traced = Enum.sum(Enum.map(result.children, & &1.traced))
    lost_children = length(result.failures)

    {twice, retraced} =
      if lost_children == 0,
        do: {max(result.duplicates, traced - total), 0},
        else: {max(result.duplicates - result.redone, 0), min(result.duplicates, result.redone)}

    image =
      if job.frames,
        do: %{messages_per_atom: per_atom(result, total)},
        else: %{
          differs: result.pixels != reference,
          atoms_differing:
            atoms_differing(result.pixels, reference, job, {result.width, result.height}),
          messages_per_atom: Result.per_atom(result).messages
        }

    Map.merge(image, %{
      twice: twice,
      retraced: retraced,
      messages: Map.new(result.messages, fn {kind, m} -> {kind, m.count} end),
      children_lost: lost_children,
      grandchild_restarts: Enum.sum(Enum.map(result.children, & &1.grandchild_restarts)),
      redone: result.redone
    })
  end

  # A sequence keeps no atom records (`Result.per_atom/1` counts those):
  # its messages over all its frames' atoms.
  defp per_atom(result, total) do
    Enum.sum(Enum.map(result.messages, fn {_, m} -> m.count end)) / total
  end

  # The atoms (of the job's layout, in one image or frame) whose pixels differ.
  defp atoms_differing(same, same, _job, _size), do: 0

  defp atoms_differing(pixels, reference, job, {w, h}) do
    layout = Layout.new(w, h, job.children, job.atoms)

    Enum.count(Layout.atoms(layout), fn atom ->
      {first, count} = Layout.span(layout, atom)
      part = fn pixels -> RingTracer.Pixels.slice(pixels, :float, first, count) end
      byte_size(pixels) != byte_size(reference) or part.(pixels) != part.(reference)
    end)
  end

  @doc """
  The totals of a report: jobs by status, faults by kind and result,
  atoms lost and traced twice, images differing, sequences and their
  frames lost, delivered twice and differing, messages per atom.
  """
  @spec totals(report()) :: map()
  def totals(%{outcomes: outcomes, pool: pool} = report) do
    faults = Enum.flat_map(outcomes, & &1.faults)
    count = fn pred -> Enum.count(outcomes, pred) end
    sum = fn key -> outcomes |> Enum.map(&Map.fetch!(&1, key)) |> Enum.sum() end
    completed = Enum.filter(outcomes, &(&1.status == :ok))
    per_atom = completed |> Enum.map(& &1.messages_per_atom) |> Enum.sort()
    {sequences, images} = Enum.split_with(outcomes, &(&1.job.frames != nil))
    sum_of = fn list, key -> list |> Enum.map(&Map.fetch!(&1, key)) |> Enum.sum() end

    %{
      jobs: length(outcomes),
      completed: length(completed),
      failed: count.(&(&1.status == :failed)),
      hung: count.(&(&1.status == :hung)),
      faults:
        Map.new(Plan.kinds(), fn kind ->
          of_kind = Enum.filter(faults, &(&1.kind == kind))

          {kind,
           %{
             injected: Enum.count(of_kind, &match?({:injected, _}, &1.result)),
             skipped: Enum.count(of_kind, &match?({:skipped, _}, &1.result))
           }}
        end),
      injected: Enum.count(faults, &match?({:injected, _}, &1.result)),
      skipped: Enum.count(faults, &match?({:skipped, _}, &1.result)),
      children_lost: sum.(:children_lost),
      grandchild_restarts: sum.(:grandchild_restarts),
      redone: sum.(:redone),
      nodes_replaced: pool.replaced,
      left_behind: report.left_behind,
      nodes_unplanned: length(pool.unplanned),
      atoms: sum.(:atoms),
      lost: sum.(:lost),
      twice: sum.(:twice),
      retraced: sum.(:retraced),
      images_differing: count.(& &1.differs),
      atoms_differing: sum_of.(images, :atoms_differing),
      sequences: length(sequences),
      sequence_faults_injected:
        sequences
        |> Enum.flat_map(& &1.faults)
        |> Enum.count(&match?({:injected, _}, &1.result)),
      frames: sum_of.(sequences, :frames),
      frames_lost: sum_of.(sequences, :frames_lost),
      frames_twice: sum_of.(sequences, :frames_twice),
      frames_differing: sum_of.(sequences, :frames_differing),
      frame_atoms_differing: sum_of.(sequences, :atoms_differing),
      median_messages_per_atom:
        if(per_atom == [], do: nil, else: Enum.at(per_atom, div(length(per_atom), 2))),
      worst: Enum.max_by(completed, & &1.messages_per_atom, fn -> nil end)
    }
  end

  @doc """
  Whether the soak passed: no atom lost or traced twice, no image
  differing, no frame lost, delivered twice or differing, no process of a
  job left behind.
  """
  @spec passed?(report()) :: boolean()
  def passed?(report) do
    t = totals(report)

    t.lost == 0 and t.twice == 0 and t.images_differing == 0 and t.frames_lost == 0 and
      t.frames_twice == 0 and t.frames_differing == 0 and t.left_behind == 0
  end

  @doc "The report as the lines the mix task prints."
  @spec format(report()) :: String.t()
  def format(%{options: opts} = report) do
    t = totals(report)

    kind_names = %{
      grandchild: "grandchild killed",
      child: "child killed",
      node: "node killed",
      freeze: "node frozen"
    }

    header =
      "chaos: seed #{opts[:seed]}, #{t.jobs} jobs (#{opts[:concurrency]} at once) on this node and " <>
        "#{opts[:nodes]} peer nodes, #{opts[:width]}x#{opts[:height]}, " <>
        "scenes #{Enum.join(opts[:scenes], ",")}, strategies #{Enum.join(opts[:strategies], ",")}, " <>
        "#{sequences(opts)}#{opts[:faults_per_job]} faults per job, liveness #{opts[:liveness]} ms, " <>
        "freeze #{opts[:freeze]} ms; #{div(report.elapsed_ms, 100) / 10} s"

    rows =
      [
        {"jobs run", t.jobs},
        {"  completed", t.completed},
        {"  failed", t.failed},
        {"  hung (cancelled)", t.hung},
        {"faults injected", t.injected}
      ] ++
        Enum.map(Plan.kinds(), fn kind -> {"  " <> kind_names[kind], t.faults[kind].injected} end) ++
        [
          {"faults skipped (no candidate, or the job had ended)", t.skipped},
          {"children lost / grandchildren restarted",
           "#{t.children_lost} / #{t.grandchild_restarts}"},
          {"atoms handed out again / re-traced after a loss", "#{t.redone} / #{t.retraced}"},
          {"nodes replaced (dropped without a fault)",
           "#{t.nodes_replaced} (#{t.nodes_unplanned})"},
          {"atoms lost", "#{t.lost} of #{t.atoms}"},
          {"atoms traced twice", t.twice},
          {"images differing (atoms)", "#{t.images_differing} (#{t.atoms_differing})"},
          {"sequences run (faults injected in them)",
           "#{t.sequences} (#{t.sequence_faults_injected})"},
          {"frames lost", "#{t.frames_lost} of #{t.frames}"},
          {"frames delivered twice", t.frames_twice},
          {"frames differing (atoms)", "#{t.frames_differing} (#{t.frame_atoms_differing})"},
          {"parents and children left on this node", t.left_behind},
          {"messages per atom: median / worst", messages(t)}
        ]

    width = rows |> Enum.map(&String.length(elem(&1, 0))) |> Enum.max()

    lines =
      Enum.map(rows, fn {label, value} ->
        "  " <> String.pad_trailing(label, width) <> "  #{value}"
      end)

    bad =
      report.outcomes
      |> Enum.filter(
        &(&1.status != :ok or &1.twice > 0 or &1.differs or &1.frames_lost > 0 or
            &1.frames_twice > 0 or &1.frames_differing > 0)
      )
      |> Enum.take(10)
      |> Enum.map(&("  job #{&1.job.index}: " <> describe(&1)))

    unplanned =
      if report.pool.unplanned == [],
        do: [],
        else: ["nodes that dropped without a fault: " <> Enum.join(report.pool.unplanned, ", ")]

    worst =
      if t.worst,
        do: ["the most messages per atom: job #{t.worst.job.index}: " <> describe(t.worst)],
        else: []

    Enum.join(
      [header | lines] ++
        worst ++ unplanned ++ if(bad == [], do: [], else: ["jobs that went wrong:" | bad]),
      "\n"
    )
  end

  defp sequences(opts) do
    if opts[:sequences] > 0,
      do:
        "sequences #{opts[:sequences]}% of jobs (#{opts[:sequence_scene]}, " <>
          "#{span(opts[:frames])} frames, window #{span(opts[:window])}), ",
      else: "no sequences, "
  end

  defp span(a..a//_), do: "#{a}"
  defp span(a..b//_), do: "#{a}-#{b}"

  defp messages(%{median_messages_per_atom: nil}), do: "-"

  defp messages(t),
    do:
      "#{fmt(t.median_messages_per_atom)} / #{fmt(t.worst.messages_per_atom)} (job #{t.worst.job.index})"

  @doc """
  One line about a job: what it was (for a sequence, its frames and
  window), its faults, what its result says
  happened (children lost, also to other jobs' node faults; grandchildren
  restarted; atoms handed out again; messages by kind) and what went wrong.
  """
  @spec describe(outcome()) :: String.t()
  def describe(o) do
    j = o.job

    messages = o.messages |> Enum.sort() |> Enum.map_join(" ", fn {kind, n} -> "#{kind} #{n}" end)

    "#{o.status}, #{j.scene}#{frames(j)}, #{j.strategy}, #{j.children} children x " <>
      "#{j.atoms} atoms, faults #{faults(o)}; children lost #{o.children_lost}, grandchildren " <>
      "restarted #{o.grandchild_restarts}, atoms redone #{o.redone}; lost #{o.lost}, twice " <>
      "#{o.twice}, #{frame_figures(o)}differing atoms #{o.atoms_differing}; " <>
      if(o.messages_per_atom,
        do: "messages per atom #{fmt(o.messages_per_atom)} (#{messages}), ",
        else: ""
      ) <>
      "#{o.elapsed_ms} ms" <> if(o.error, do: "; #{o.error}", else: "")
  end

  defp frames(%{frames: nil}), do: ""
  defp frames(j), do: " frames #{Enum.join(j.frames, ",")} (window #{j.window})"

  defp frame_figures(%{job: %{frames: nil}}), do: ""

  defp frame_figures(o),
    do: "frames lost #{o.frames_lost}, twice #{o.frames_twice}, differing #{o.frames_differing}, "

  defp faults(o) do
    o.faults
    |> Enum.map(fn f ->
      case f.result do
        {:injected, what} -> "#{f.kind}@#{f.at} #{what}"
        {:skipped, why} -> "#{f.kind}@#{f.at} skipped (#{why})"
      end
    end)
    |> case do
      [] -> "none"
      list -> Enum.join(list, ", ")
    end
  end

  defp fmt(x), do: :erlang.float_to_binary(x / 1, decimals: 2)
end
