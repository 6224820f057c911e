defmodule RingTracer.Chaos.Plan do
  @moduledoc false
  # The chaos soak's plan (`RingTracer.Chaos`), a pure function of its seed:
  # for each job, its scene, strategy, ring size, atoms per child, the
  # children's slowdown factors and the faults to inject, each at an atom
  # count (the fault is injected when the job's parent reports that many atoms
  # done) with a number that picks its victim among the candidates alive at
  # that moment (`pick`, taken modulo the number of candidates).
  #
  # A share of the jobs (`:sequences`, in percent) are sequences
  # (`RingTracer.render_sequence/2`) of an animated scene: a few of its
  # frames (`:frames`, an ascending list drawn from the scene's), through a
  # window of `:window` frames. Their faults are due at atom counts over the
  # whole sequence (the job's progress counts every frame's atoms), so they
  # land in any of its frames or between two. An image job has `frames: nil`
  # and `window: nil`.
  #
  # Fault kinds:
  #
  #   * `:grandchild` — kill a child's grandchild (the child restarts it and
  #     retries its atoms);
  #   * `:child` — kill a child (the parent re-links the ring and hands out
  #     its atoms again);
  #   * `:node` — kill the OS process of a peer node that hosts children of
  #     the job (a crashed machine);
  #   * `:freeze` — stop a peer node's OS process with SIGSTOP and resume it
  #     later (a hung machine: the job's liveness watch must declare it dead).

  @typedoc "A fault kind."
  @type kind :: :grandchild | :child | :node | :freeze

  @typedoc "One planned fault: its kind, the atom count it waits for, its victim's pick."
  @type fault :: %{kind: kind(), at: pos_integer(), pick: non_neg_integer()}

  @typedoc "One planned job."
  @type job :: %{
          index: non_neg_integer(),
          scene: String.t(),
          strategy: atom(),
          children: pos_integer(),
          atoms: pos_integer(),
          speeds: [pos_integer()],
          frames: [pos_integer()] | nil,
          window: pos_integer() | nil,
          faults: [fault()]
        }

  @kinds [:grandchild, :child, :node, :freeze]
  @default_weights [grandchild: 3, child: 3, node: 1, freeze: 1]
  @picks 1_073_741_824

  @doc "The fault kinds, in the order the report lists them."
  @spec kinds() :: [kind()]
  def kinds, do: @kinds

  @doc "How often each kind is drawn by default, relative to the others."
  @spec default_weights() :: keyword(non_neg_integer())
  def default_weights, do: @default_weights

  @doc """
  The plan of `opts[:jobs]` jobs.

  ## Options

    * `:seed` — integer (default 1)
    * `:jobs` — number of jobs (default 100)
    * `:scenes` — scene names, drawn at random for each job (required)
    * `:strategies` — drawn at random for each job (default `[:ring]`)
    * `:children` — range of ring sizes (default `3..6`)
    * `:atoms` — range of atoms per child (default `4..8`)
    * `:slowdown` — range of each child's slowdown factor (default
      `300..1000`: atoms of a small image then take milliseconds, long
      enough for faults to land while the job runs)
    * `:faults_per_job` — faults planned per job (default 2)
    * `:weights` — keyword of kind to weight (default `default_weights/0`)
    * `:sequences` — the percentage of jobs drawn as sequences, 0 to 100
      (default 0)
    * `:sequence_scene` — the animated scene of the sequences (required
      when `:sequences` is above 0)
    * `:scene_frames` — how many frames that scene has (required when
      `:sequences` is above 0: the plan reads no file)
    * `:frames` — range of how many of its frames a sequence renders
      (default `2..4`; at most `:scene_frames`), drawn among all its frames
    * `:window` — range of a sequence's window (default `1..3`)

  Whether a job is a sequence, and its frames and window, are drawn apart
  from the rest: a job that is not a sequence is the same whatever the
  sequence options, and a sequence differs from the image job it replaces
  only in its scene, frames, window and its faults' atom counts (their
  kinds and picks are the same).

      iex> plan = RingTracer.Chaos.Plan.new(seed: 7, jobs: 3, scenes: ["a.nff", "b.nff"])
      iex> length(plan)
      3
      iex> plan == RingTracer.Chaos.Plan.new(seed: 7, jobs: 3, scenes: ["a.nff", "b.nff"])
      true
      iex> Enum.all?(plan, &(length(&1.faults) == 2))
      true
      iex> plan = RingTracer.Chaos.Plan.new(seed: 7, jobs: 20, scenes: ["a.nff"], sequences: 50,
      ...>   sequence_scene: "orbit.toml", scene_frames: 48, frames: 2..5, window: 1..3)
      iex> [job | _] = Enum.filter(plan, & &1.frames)
      iex> {job.scene, length(job.frames) in 2..5, job.frames == Enum.sort(Enum.uniq(job.frames))}
      {"orbit.toml", true, true}
  """
  @spec new(keyword()) :: [job()]
  def new(opts) do
    scenes = Keyword.fetch!(opts, :scenes)
    strategies = Keyword.get(opts, :strategies, [:ring])
    children = Keyword.get(opts, :children, 3..6)
    atoms = Keyword.get(opts, :atoms, 4..8)
    slowdown = Keyword.get(opts, :slowdown, 300..1000)
    faults = Keyword.get(opts, :faults_per_job, 2)
    weights = Keyword.get(opts, :weights, @default_weights)
    seed = Keyword.get(opts, :seed, 1)
    sequence = sequence_options(opts)
    rand = :rand.seed_s(:exsss, {seed, 18, 9})

    {jobs, _} =
      Enum.map_reduce(0..(Keyword.get(opts, :jobs, 100) - 1)//1, rand, fn index, rand ->
        {scene, rand} = pick(scenes, rand)
        {strategy, rand} = pick(strategies, rand)
        {n, rand} = in_range(children, rand)
        {k, rand} = in_range(atoms, rand)
        {speeds, rand} = many(n, rand, &in_range(slowdown, &1))
        {frames, window} = sequence(sequence, seed, index)
        {faults, rand} = many(faults, rand, &fault(&1, weights, n * k * length(frames || [1])))

        job = %{
          index: index,
          scene: if(frames, do: sequence.scene, else: scene),
          strategy: strategy,
          children: n,
          atoms: k,
          speeds: speeds,
          frames: frames,
          window: window,
          faults: Enum.sort_by(faults, & &1.at)
        }

        {job, rand}
      end)

    jobs
  end

  defp sequence_options(opts) do
    case Keyword.get(opts, :sequences, 0) do
      0 ->
        nil

      percent when percent in 1..100 ->
        count = Keyword.fetch!(opts, :scene_frames)
        first..last//_ = Keyword.get(opts, :frames, 2..4)

        %{
          percent: percent,
          scene: Keyword.fetch!(opts, :sequence_scene),
          count: count,
          frames: min(first, count)..min(last, count),
          window: Keyword.get(opts, :window, 1..3)
        }

      other ->
        raise ArgumentError,
              ":sequences must be a percentage from 0 to 100, got: #{inspect(other)}"
    end
  end

  # Whether a job is a sequence, and which, is drawn from a stream of its
  # own: the other draws (a fault's atom count takes one draw whatever its
  # range) are those of the same seed without sequences.
  defp sequence(nil, _seed, _index), do: {nil, nil}

  defp sequence(s, seed, index) do
    rand = :rand.seed_s(:exsss, {seed, 41, index})
    {x, rand} = :rand.uniform_s(100, rand)

    if x <= s.percent do
      {count, rand} = in_range(s.frames, rand)
      {frames, rand} = subset(Enum.to_list(1..s.count), count, rand)
      {window, _} = in_range(s.window, rand)
      {Enum.sort(frames), window}
    else
      {nil, nil}
    end
  end

  # `count` distinct members of `list`.
  defp subset(_list, 0, rand), do: {[], rand}

  defp subset(list, count, rand) do
    {i, rand} = :rand.uniform_s(length(list), rand)
    {x, rest} = List.pop_at(list, i - 1)
    {more, rand} = subset(rest, count - 1, rand)
    {[x | more], rand}
  end

  defp fault(rand, weights, total) do
    {kind, rand} = weighted(weights, rand)
    # At least one atom in (so the ring runs), at most all but one.
    {at, rand} = in_range(1..max(total - 1, 1), rand)
    {pick, rand} = :rand.uniform_s(@picks, rand)
    {%{kind: kind, at: at, pick: pick - 1}, rand}
  end

  defp many(0, rand, _fun), do: {[], rand}

  defp many(n, rand, fun) do
    Enum.map_reduce(1..n, rand, fn _, rand -> fun.(rand) end)
  end

  defp pick(list, rand) do
    {i, rand} = :rand.uniform_s(length(list), rand)
    {Enum.at(list, i - 1), rand}
  end

  defp in_range(first..last//_, rand) do
    {i, rand} = :rand.uniform_s(last - first + 1, rand)
    {first + i - 1, rand}
  end

  defp weighted(weights, rand) do
    weights = Enum.filter(weights, fn {_, w} -> w > 0 end)
    {x, rand} = :rand.uniform_s(Enum.sum(Enum.map(weights, &elem(&1, 1))), rand)

    kind =
      Enum.reduce_while(weights, x, fn {kind, w}, left ->
        if left <= w, do: {:halt, kind}, else: {:cont, left - w}
      end)

    {kind, rand}
  end
end
