defmodule RingTracer.Farm.JobInfo do
  @moduledoc """
  A farm job as `RingTracer.Farm.jobs/1` and `RingTracer.Farm.status/2`
  show it: who submitted it, how it is to run, where it stands.

    * `:state` — `:queued` (waiting for workers), `:running`, `:done`,
      `:failed` (`:error` says why) or `:cancelled`
    * `:frames` — the scene's frames it renders (from 1; a still is `[1]`),
      `:done` those complete and stored on the head
    * `:workers` — the worker nodes its ring uses now
    * `:format` — `:png` or `:exr`, what the head stores and
      `RingTracer.Farm.frame/3` returns; `:out` the submitter's output
      pattern, kept for `wait` and `fetch`
    * times in milliseconds since the epoch (`System.os_time(:millisecond)`)
  """

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
          priority: integer(),
          tags: [String.t()],
          max_workers: pos_integer() | nil,
          frames: [pos_integer()],
          done: [pos_integer()],
          workers: [node()]
        }
end
