defmodule RingTracer.Chaos.Farm.Checker do
  @moduledoc false
  # The farm soak's verdict, a pure function of what the soak collected: each
  # job's end state, each frame asked for with the hash of what the head
  # stored (`nil`: the head has no such frame) and of the same frame rendered
  # alone, and the head's count of frames stored twice
  # (`RingTracer.Farm.overview/2`'s `:stored_twice`).

  defmodule JobEnd do
    @moduledoc false
    # A job of the soak as it ended: its index in the schedule, id and state.
    @enforce_keys [:index, :id, :state]
    defstruct [:index, :id, :state, error: nil]

    @type t :: %__MODULE__{
            index: non_neg_integer(),
            id: pos_integer() | nil,
            state: :done | :failed | :cancelled | :queued | :running | :unknown,
            error: String.t() | nil
          }
  end

  defmodule Frame do
    @moduledoc false
    # A frame asked for: the hash of the file the head stored (`nil`: none)
    # and of the same frame rendered alone on the soak's node.
    @enforce_keys [:index, :number, :got, :expected]
    defstruct [:index, :number, :got, :expected]

    @type t :: %__MODULE__{
            index: non_neg_integer(),
            number: pos_integer(),
            got: binary() | nil,
            expected: binary()
          }
  end

  @enforce_keys [:jobs, :done, :frames, :lost, :twice, :mismatches, :wrong]
  defstruct [:jobs, :done, :frames, :lost, :twice, :mismatches, :wrong]

  @typedoc """
  The verdict: jobs and those done, frames asked for, frames lost (not
  stored), stored twice, stored but differing from the frame rendered
  alone, and the indexes of the jobs that went wrong.
  """
  @type t :: %__MODULE__{
          jobs: non_neg_integer(),
          done: non_neg_integer(),
          frames: non_neg_integer(),
          lost: non_neg_integer(),
          twice: non_neg_integer(),
          mismatches: non_neg_integer(),
          wrong: [non_neg_integer()]
        }

  @doc """
  The verdict over the jobs' ends, their frames and the frames stored twice.

      iex> alias RingTracer.Chaos.Farm.Checker
      iex> alias RingTracer.Chaos.Farm.Checker.{Frame, JobEnd}
      iex> v = Checker.check([%JobEnd{index: 0, id: 1, state: :done}],
      ...>   [%Frame{index: 0, number: 1, got: "h", expected: "h"}], 0)
      iex> {Checker.passed?(v), v.lost, v.mismatches}
      {true, 0, 0}
  """
  @spec check([JobEnd.t()], [Frame.t()], non_neg_integer()) :: t()
  def check(ends, frames, stored_twice) do
    lost = Enum.filter(frames, &is_nil(&1.got))
    mismatched = Enum.filter(frames, &(&1.got != nil and &1.got != &1.expected))
    not_done = for %JobEnd{state: s, index: i} <- ends, s != :done, do: i

    %__MODULE__{
      jobs: length(ends),
      done: length(ends) - length(not_done),
      frames: length(frames),
      lost: length(lost),
      twice: stored_twice,
      mismatches: length(mismatched),
      wrong: Enum.sort(Enum.uniq(not_done ++ Enum.map(lost ++ mismatched, & &1.index)))
    }
  end

  @doc "Whether every job is done and no frame was lost, stored twice or differs."
  @spec passed?(t()) :: boolean()
  def passed?(%__MODULE__{} = v),
    do: v.done == v.jobs and v.lost == 0 and v.twice == 0 and v.mismatches == 0
end
