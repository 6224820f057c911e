defmodule RingTracer.Farm.Job do
  @moduledoc false
  # A farm job as the head keeps it in Mnesia: what was submitted (the
  # scene's source with its files' bytes, the render options), how the farm
  # is to run it, and where it stands. Frames done are rows of their own
  # (`RingTracer.Farm.Store`).

  alias RingTracer.Scene.Source

  @type state :: :queued | :running | :done | :failed | :cancelled

  @enforce_keys [:id, :user, :source, :options, :frames, :format]
  defstruct [
    :id,
    :user,
    :source,
    :options,
    :frames,
    :format,
    :width,
    :height,
    out: nil,
    priority: 0,
    tags: [],
    max_workers: nil,
    state: :queued,
    submitted_at: nil,
    started_at: nil,
    finished_at: nil,
    error: nil,
    tries: 0
  ]

  @type t :: %__MODULE__{
          id: pos_integer(),
          user: String.t(),
          source: Source.t(),
          options: keyword(),
          frames: [pos_integer()],
          format: :png | :exr,
          width: pos_integer() | nil,
          height: pos_integer() | nil,
          out: String.t() | nil,
          priority: integer(),
          tags: [String.t()],
          max_workers: pos_integer() | nil,
          state: state(),
          submitted_at: integer() | nil,
          started_at: integer() | nil,
          finished_at: integer() | nil,
          error: String.t() | nil,
          tries: non_neg_integer()
        }

  @doc "Whether the job will not run again."
  @spec ended?(t()) :: boolean()
  def ended?(%__MODULE__{state: state}), do: ended_state?(state)

  @doc "Whether a job in `state` has ended: done, failed or cancelled."
  @spec ended_state?(atom()) :: boolean()
  def ended_state?(state), do: state in [:done, :failed, :cancelled]

  @doc "The file name a frame of the job is stored under on the head."
  @spec frame_file(t(), pos_integer()) :: String.t()
  def frame_file(%__MODULE__{id: id, format: format}, n),
    do: "#{id}_#{String.pad_leading(Integer.to_string(n), 6, "0")}.#{format}"
end
