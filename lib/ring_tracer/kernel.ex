defmodule RingTracer.Kernel do
  @moduledoc false
  # What a grandchild calls to trace an atom. Two implementations share the
  # same parent, children and strategies:
  #
  #   * `RingTracer.Kernel.Native` — the Rust ray tracer, through the NIF;
  #   * `RingTracer.Kernel.Simulated` — a cost model that sleeps for each atom's
  #     cost instead of tracing, so that hundreds of children fit on one machine.
  #
  # A job's spec names the kernel as `{module, options}`.

  alias RingTracer.Job.Spec

  @typedoc "Whatever `prepare/2` returns, passed back to `trace/4`."
  @type context :: term()

  @doc "Prepares tracing on the calling process's node (e.g. fetches the parsed scene)."
  @callback prepare(Spec.t(), keyword()) :: {:ok, context()} | {:error, String.t()}

  @doc """
  Prepares the calling process's node for the job's children, once per
  node, before they start there (`RingTracer.Job.Host`, called by the
  parent on every node at once): e.g. pins the job's scene there for as
  long as `owner`, the job's parent, lives. Returns `:need_scene` when the
  spec's scene came by hash only and this node does not hold it; the
  parent then sends it packed.
  """
  @callback prepare_node(Spec.t(), keyword(), owner :: pid()) ::
              :ok | :need_scene | {:error, String.t()}

  @doc """
  Traces `count` pixels from `first`, atom number `atom`: linear RGB as
  native-endian f32 triples, the ray counters (`no_rays/0`'s keys), and the
  microseconds it took.

  The counters' `:work` is the atom's cost in the kernel's own units, the
  same on every machine (for the native kernel: BVH nodes visited plus
  primitives tested plus rays). The ring's share rule measures a child's
  speed in work per microsecond: counting atoms would mix up speed with
  atom cost.
  """
  @callback trace(context(), non_neg_integer(), non_neg_integer(), RingTracer.Layout.atom_id()) ::
              {:ok, binary(), map(), non_neg_integer()} | {:error, String.t()}

  @doc """
  Optional: an estimate of each atom's work, in the `:work` units of
  `trace/4`, as a tuple by atom, for strategies that send help where the
  work is (`RingTracer.Strategy.Ring.Aim`). Called once per job, on the parent's
  node, while the children start.
  """
  @callback atom_work(Spec.t(), keyword()) :: {:ok, tuple()} | {:error, String.t()}

  @optional_callbacks atom_work: 2

  @doc "Zeroed ray counters (and work units): `RingTracer.Rays.zero/0`."
  @spec no_rays() :: RingTracer.Rays.t()
  def no_rays, do: RingTracer.Rays.zero()
end
