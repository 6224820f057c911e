defmodule RingTracer.Chaos.Farm.Schedule do
  @moduledoc false
  # The farm soak's schedule (`RingTracer.Chaos.Farm.Soak`), a pure function
  # of its options: the jobs to queue (stills and short sequences, from two
  # users, with drawn priorities, tags and formats) and the faults to inject,
  # each due when the farm has stored a given number of frames in all.

  defmodule JobSpec do
    @moduledoc false
    # One job of the schedule: what is submitted, and by whom.
    @enforce_keys [:index, :user, :priority, :tags, :scene, :frames, :format]
    defstruct [:index, :user, :priority, :tags, :scene, :frames, :format]

    @typedoc "`frames`: the scene's frames, from 1 (a still is `[1]`)."
    @type t :: %__MODULE__{
            index: non_neg_integer(),
            user: String.t(),
            priority: non_neg_integer(),
            tags: [String.t()],
            scene: String.t(),
            frames: [pos_integer()],
            format: :png | :exr
          }
  end

  defmodule Fault do
    @moduledoc false
    # One fault: its kind, the frames stored in all (over every job) at which
    # it is due, and a number that picks its victim among the workers up then.
    @enforce_keys [:kind, :at, :pick]
    defstruct [:kind, :at, :pick]

    @type kind :: :head_kill | :worker_kill | :worker_freeze | :worker_add
    @type t :: %__MODULE__{kind: kind(), at: pos_integer(), pick: non_neg_integer()}
  end

  @enforce_keys [:seed, :jobs, :faults]
  defstruct [:seed, :jobs, :faults]

  @type t :: %__MODULE__{seed: integer(), jobs: [JobSpec.t()], faults: [Fault.t()]}

  @kinds [:head_kill, :worker_kill, :worker_freeze, :worker_add]
  @stills ["balls_s2.nff", "tetra_s3.nff", "whitted.toml"]
  @users ["ann", "bob"]
  @tag "soak"
  @picks 1_073_741_824

  @doc "The fault kinds, in the order the summary lists them."
  @spec kinds() :: [Fault.kind()]
  def kinds, do: @kinds

  @doc "The tag every worker of the soak has (a job may ask for it)."
  @spec tag() :: String.t()
  def tag, do: @tag

  @doc """
  The schedule.

  ## Options

    * `:seed` — integer (default 1)
    * `:jobs` — jobs to queue (default 60)
    * `:sequence_scene` — the animated scene of the sequences (default
      `"whitted_orbit.toml"`) and `:scene_frames`, its frame count (default 48)
    * `:faults` — how many of each kind, a keyword list (default, for `n`
      jobs: a head kill per 20 jobs, a worker killed, frozen and added per
      10, at least one each)

      iex> alias RingTracer.Chaos.Farm.Schedule
      iex> s = Schedule.new(seed: 3, jobs: 8)
      iex> {length(s.jobs), s == Schedule.new(seed: 3, jobs: 8)}
      {8, true}
  """
  @spec new(keyword()) :: t()
  def new(opts \\ []) do
    seed = Keyword.get(opts, :seed, 1)
    count = Keyword.get(opts, :jobs, 60)
    sequence_scene = Keyword.get(opts, :sequence_scene, "whitted_orbit.toml")
    scene_frames = Keyword.get(opts, :scene_frames, 48)
    rand = :rand.seed_s(:exsss, {seed, 7919, 104_729})

    {jobs, rand} =
      Enum.map_reduce(0..(count - 1)//1, rand, fn index, rand ->
        job(index, rand, sequence_scene, scene_frames)
      end)

    total = jobs |> Enum.map(&length(&1.frames)) |> Enum.sum()
    counts = Keyword.get(opts, :faults, default_faults(count))
    {faults, _} = faults(counts, total, rand)
    %__MODULE__{seed: seed, jobs: jobs, faults: faults}
  end

  @doc "The frames of every job, in all."
  @spec frames(t()) :: non_neg_integer()
  def frames(%__MODULE__{jobs: jobs}), do: jobs |> Enum.map(&length(&1.frames)) |> Enum.sum()

  defp default_faults(jobs) do
    [
      head_kill: max(1, div(jobs, 20)),
      worker_kill: max(1, div(jobs, 10)),
      worker_freeze: max(1, div(jobs, 10)),
      worker_add: max(1, div(jobs, 10))
    ]
  end

  defp job(index, rand, sequence_scene, scene_frames) do
    {user, rand} = pick(@users, rand)
    {priority, rand} = uniform(4, rand)
    {tagged, rand} = uniform(2, rand)
    {still, rand} = uniform(2, rand)
    {exr, rand} = uniform(4, rand)
    {scene, frames, rand} = scene(still == 1, rand, sequence_scene, scene_frames)

    job = %JobSpec{
      index: index,
      user: user,
      priority: priority - 1,
      tags: if(tagged == 1, do: [@tag], else: []),
      scene: scene,
      frames: frames,
      format: if(exr == 1, do: :exr, else: :png)
    }

    {job, rand}
  end

  defp scene(true, rand, sequence_scene, scene_frames) do
    {n, rand} = uniform(length(@stills) + 1, rand)

    case Enum.at(@stills, n - 1) do
      nil ->
        {frame, rand} = uniform(scene_frames, rand)
        {sequence_scene, [frame], rand}

      still ->
        {still, [1], rand}
    end
  end

  defp scene(false, rand, sequence_scene, scene_frames) do
    {count, rand} = uniform(3, rand)
    {first, rand} = uniform(scene_frames - count, rand)
    # count + 1 frames, every other one: ascending, never the same twice.
    {sequence_scene, Enum.to_list(first..min(first + 2 * count, scene_frames)//2), rand}
  end

  # Each fault due at a frame count drawn over the first 70% of the frames,
  # so that it lands while the queue still runs.
  defp faults(counts, total, rand) do
    span = max(1, div(total * 7, 10))

    {faults, rand} =
      counts
      |> Enum.flat_map(fn {kind, n} when kind in @kinds -> List.duplicate(kind, n) end)
      |> Enum.map_reduce(rand, fn kind, rand ->
        {at, rand} = uniform(span, rand)
        {pick, rand} = uniform(@picks, rand)
        {%Fault{kind: kind, at: at, pick: pick - 1}, rand}
      end)

    {Enum.sort_by(faults, & &1.at), rand}
  end

  defp pick(list, rand) do
    {n, rand} = uniform(length(list), rand)
    {Enum.at(list, n - 1), rand}
  end

  defp uniform(n, rand), do: :rand.uniform_s(max(n, 1), rand)
end
