defmodule RingTracer.Strategy.View do
  @moduledoc """
  What a child's strategy sees of its child: read-only, built by the child
  for each callback.

    * `:job` — the job's id; `:options` — the strategy's options;
    * `:index`, `:pid` — the child's place in the ring and its pid;
      `:ring_size` — children in the ring so far, at the start and joined
      since (`RingTracer.grow/4`; indices `0..ring_size - 1`);
      `:left`, `:left_index` — its left sibling now; `:dead` — siblings
      known to be dead or gone;
    * `:status` — `:working` (atoms queued or in its pipe), `:idle` (its
      strategy was told it ran out, and has not made it finish) or
      `:finished`;
    * `:queued` — atoms queued, not yet in the grandchild's pipe;
      `:remaining`, `:in_flight` — what it could give: the queued atoms plus
      the one waiting in its pipe, and the one being traced;
      `:last_share` — the share of its atom (1.0: a whole atom, less for a
      piece, see `RingTracer.Layout`) of the farthest atom it could give
      (`nil`: none);
    * `:done` — atoms traced; `:rate` — its speed, kernel work per busy
      microsecond (`nil` before it has traced work); `:mean_atom_us` — wall
      time per atom (`nil` before its first); `:remaining_us` — how long the
      atom being traced should still take (`nil` when none or unknown);
      `:cuttable` — parts of the atom being traced not yet started, where
      its grandchild traces it in parts (`RingTracer.Job.Pipe.cut/3`; 0:
      none); `:next_rows` — image rows in the atom it puts in the pipe
      next (for `RingTracer.Strategy.parts/2`; 0.0 elsewhere);
    * `:more_frames` — whether the job has frames still to come, that
      the parent has not released yet (`RingTracer.Strategy.parent_frame/3`):
      a finished child may then get work again;
    * `:now` — job microseconds (wall clock since the job's start, the
      same for every process of the job).
  """

  @enforce_keys [:job, :index, :pid, :ring_size, :status]
  defstruct [
    :job,
    :index,
    :pid,
    :ring_size,
    :left,
    :left_index,
    :status,
    :rate,
    :mean_atom_us,
    :remaining_us,
    :last_share,
    options: [],
    dead: [],
    queued: 0,
    remaining: 0,
    in_flight: 0,
    done: 0,
    cuttable: 0,
    next_rows: 0.0,
    more_frames: false,
    now: 0
  ]

  @type t :: %__MODULE__{
          job: reference(),
          options: keyword(),
          index: non_neg_integer(),
          pid: pid(),
          ring_size: non_neg_integer(),
          left: pid() | nil,
          left_index: non_neg_integer() | nil,
          dead: [non_neg_integer()],
          status: :working | :idle | :finished,
          queued: non_neg_integer(),
          remaining: non_neg_integer(),
          last_share: float() | nil,
          in_flight: non_neg_integer(),
          done: non_neg_integer(),
          rate: float() | nil,
          mean_atom_us: non_neg_integer() | nil,
          remaining_us: non_neg_integer() | nil,
          cuttable: non_neg_integer(),
          next_rows: float(),
          more_frames: boolean(),
          now: integer()
        }
end
