defmodule RingTracer.Job.Spec do
  @moduledoc false
  # Everything a job's processes need to know, built once by `RingTracer.render/2`
  # and handed to the parent, which hands each child its part. It holds the
  # scene's source (bytes), never a scene handle, so it can cross nodes, and
  # which frames of an animated scene to trace (`frames`, from 0: the scene's
  # frame for each of the layout's frames, in order; `RingTracer.Layout`,
  # "Frames"); in a `sequence`, how many frames may be in flight at once
  # (`window`), and the caller gets each frame as it completes instead of one
  # image at the end; with `ack`, a frame leaves the window only once the
  # caller acknowledges it. With `announce` (jobs started through a handle,
  # `RingTracer.render_async/2` and `RingTracer.render_sequence/2`) the
  # parent tells the progress pid its own pid, so that the handle reaches
  # it (`RingTracer.grow/4`, `RingTracer.ack_frame/2`). `pixels` is the
  # format of the job's pixels (`RingTracer.Pixels`): the grandchildren send
  # them in it and the parent assembles them in it; with `tint` (a job in
  # `:srgb8` that writes an ownership map) they also send each atom tinted
  # with their child's colour (`RingTracer.Report.Ownership`).

  alias RingTracer.{Layout, Settings}
  alias RingTracer.Scene.Source

  @enforce_keys [:id, :source, :settings, :layout, :caller]
  defstruct [
    :id,
    :source,
    :settings,
    :layout,
    :caller,
    nodes: [],
    strategy: {RingTracer.Strategy.Ring, []},
    kernel: {RingTracer.Kernel.Native, []},
    speeds: [],
    progress: nil,
    frames: [0],
    window: 1,
    sequence: false,
    ack: false,
    announce: false,
    pixels: :float,
    tint: false,
    liveness: RingTracer.Cluster.Liveness.default_timeout()
  ]

  @type t :: %__MODULE__{
          id: reference(),
          source: Source.t(),
          settings: Settings.t(),
          layout: Layout.t(),
          caller: pid(),
          nodes: [node()],
          strategy: RingTracer.Strategy.t(),
          kernel: {module(), keyword()},
          speeds: [number()],
          progress: pid() | nil,
          frames: [non_neg_integer(), ...],
          window: pos_integer(),
          sequence: boolean(),
          ack: boolean(),
          announce: boolean(),
          pixels: RingTracer.Pixels.format(),
          tint: boolean(),
          liveness: pos_integer()
        }

  @doc """
  Child `index`'s slowdown from the job's speeds, as a tuple (they repeat
  over the ring; none means 1).

      iex> RingTracer.Job.Spec.speed({1, 4}, 3)
      4
      iex> RingTracer.Job.Spec.speed({}, 3)
      1
  """
  @spec speed(tuple(), non_neg_integer()) :: number()
  def speed({}, _index), do: 1
  def speed(speeds, index), do: elem(speeds, rem(index, tuple_size(speeds)))
end
