defmodule RingTracer.Farm.WorkerInfo do
  @moduledoc false
  # A worker of a farm as `RingTracer.Farm.workers/1` shows it: its node, the
  # tags it was started with, how many children it hosts for a job
  # (`:slots`), the job it works for now (`nil`: idle) and when it joined
  # (milliseconds since the epoch). `:speed` is 1 but for a worker that
  # emulates a slower machine (`RingTracer.Farm.join/2`).

  @enforce_keys [:node]
  defstruct [:node, :job, :joined_at, tags: [], slots: 1, speed: 1]

  @type t :: %__MODULE__{
          node: node(),
          job: pos_integer() | nil,
          joined_at: integer() | nil,
          tags: [String.t()],
          slots: pos_integer(),
          speed: number()
        }
end
