defmodule RingTracer.Farm.JobInfo do
  @moduledoc false
  # A farm job as `RingTracer.Farm.jobs/1` and `RingTracer.Farm.status/2`
  # show it: who submitted it, how it is to run, where it stands.
  #
  #   * `:state` — `:queued` (waiting for workers), `:running`, `:done`,
  #     `:failed` (`:error` says why) or `:cancelled`
  #   * `:frames` — the scene's frames it renders (from 1; a still is `[1]`),
  #     `:done` those complete and stored on the head
  #   * `:workers` — the worker nodes its ring uses now
  #   * `:format` — `:png` or `:exr`, what the head stores and
  #     `RingTracer.Farm.frame/3` returns; `:out` the submitter's output
  #     pattern, kept for `wait` and `fetch`
  #   * `:progress` — how much of the job is done, from 0.0 to 1.0: its
  #     frames done and, while it runs, its ring's atoms traced
  #   * `:time_left` — while it runs and once its ring has traced an atom,
  #     an estimate of the milliseconds left, at the ring's rate so far
  #     (`estimate/4`); otherwise nil
  #   * `:preview` — while it runs on a head with a dashboard, the address
  #     of its ring's live preview (`RingTracer.Preview`, on the head's
  #     loopback, with its own token)
  #   * times in milliseconds since the epoch (`System.os_time(:millisecond)`)

  @enforce_keys [:id, :user, :state]
  defstruct [
    :id,
    :user,
    :state,
    :scene,
    :width,
    :height,
    :format,
    :out,
    :submitted_at,
    :started_at,
    :finished_at,
    :error,
    :time_left,
    :preview,
    progress: 0.0,
    priority: 0,
    tags: [],
    max_workers: nil,
    frames: [],
    done: [],
    workers: []
  ]

  @type t :: %__MODULE__{
          id: pos_integer(),
          user: String.t(),
          state: :queued | :running | :done | :failed | :cancelled,
          scene: String.t() | nil,
          width: pos_integer() | nil,
          height: pos_integer() | nil,
          format: :png | :exr | nil,
          out: String.t() | nil,
          submitted_at: integer() | nil,
          started_at: integer() | nil,
          finished_at: integer() | nil,
          error: String.t() | nil,
          time_left: non_neg_integer() | nil,
          preview: String.t() | nil,
          progress: float(),
          priority: integer(),
          tags: [String.t()],
          max_workers: pos_integer() | nil,
          frames: [pos_integer()],
          done: [pos_integer()],
          workers: [node()]
        }

  @doc """
  A job's progress and time left: `frames` to render, `done` of them
  complete, and of the ring running now (nil when none runs) the frames it
  was started for, its atoms traced of its total and the milliseconds since
  it started.

      iex> RingTracer.Farm.JobInfo.estimate(4, 2, nil, 0)
      {0.5, nil}
      iex> RingTracer.Farm.JobInfo.estimate(4, 0, {4, {30, 120}}, 3_000)
      {0.25, 9000}
      iex> RingTracer.Farm.JobInfo.estimate(1, 0, {1, {0, 16}}, 500)
      {0.0, nil}
  """
  @spec estimate(
          non_neg_integer(),
          non_neg_integer(),
          {non_neg_integer(), {non_neg_integer(), non_neg_integer()} | nil} | nil,
          non_neg_integer()
        ) :: {float(), non_neg_integer() | nil}
  def estimate(0, _done, _run, _elapsed), do: {1.0, nil}

  def estimate(frames, done, {run_frames, {atoms, total}}, elapsed)
      when atoms > 0 and total > 0 do
    ratio = min(atoms / total, 1.0)
    # Frames done before this ring started, then this ring's share.
    before = max(frames - run_frames, 0)
    fraction = min((before + ratio * run_frames) / frames, 1.0)
    {max(fraction, done / frames), round(elapsed * max(total - atoms, 0) / atoms)}
  end

  def estimate(frames, done, _run, _elapsed), do: {done / frames, nil}
end
