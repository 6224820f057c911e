defmodule RingTracer.Strategy.ParentView do
  @moduledoc """
  What a strategy sees of the job's parent: read-only, built by the parent
  for each callback.

    * `:spec` — the job's spec (`RingTracer.Job.Spec`: its layout, kernel,
      id); `:options` — the strategy's options; `:pid` — the parent's pid;
    * `:children` — the living children, index to pid; `:size` — how many
      children the job has started, those that joined it included
      (indices `0..size - 1`; 0 is read as the layout's children);
    * `:traced_by` — each atom received so far, to the child that traced it;
    * `:now` — job microseconds.
  """

  @enforce_keys [:spec, :pid]
  defstruct [:spec, :pid, options: [], children: %{}, size: 0, traced_by: %{}, now: 0]

  @type t :: %__MODULE__{
          spec: RingTracer.Job.Spec.t(),
          options: keyword(),
          pid: pid(),
          children: %{non_neg_integer() => pid()},
          size: non_neg_integer(),
          traced_by: %{RingTracer.Layout.atom_id() => non_neg_integer()},
          now: integer()
        }
end
