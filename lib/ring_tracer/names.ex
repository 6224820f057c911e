defmodule RingTracer.Names do
  @moduledoc """
  Every registered name RingTracer uses, built in one place.

  Per node: the jobs supervisor (parents), the children supervisor (children
  started on this node by any job's parent), the scene cache and the
  tables of the job directory and the grandchildren's pipes.
  """

  @doc "Supervisor of parents, one per running job, on this node."
  @spec jobs() :: atom()
  def jobs, do: RingTracer.Jobs

  @doc "Supervisor of children on `node`, as a reference usable from any node."
  @spec children(node()) :: atom() | {atom(), node()}
  def children(node \\ node())
  def children(node) when node == node(), do: RingTracer.Children
  def children(node), do: {RingTracer.Children, node}

  @doc "The ETS table, on every node, where a job's children look each other up."
  @spec directory_table() :: atom()
  def directory_table, do: :ring_tracer_directory

  @doc "The ETS table, on every node, where a child and its grandchild race for the queued atom."
  @spec pipe_table() :: atom()
  def pipe_table, do: :ring_tracer_pipe
end
