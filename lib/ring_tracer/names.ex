defmodule RingTracer.Names do
  @moduledoc false
  # Every registered name RingTracer uses, built in one place.
  #
  # Per node: the jobs supervisor (parents), the children supervisor (children
  # started on this node by any job's parent), the scene cache and the
  # tables of the job directory and the grandchildren's pipes.

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

  @doc "A farm's head process, on the head node (`node` another one: the address to call)."
  @spec farm_head(node()) :: atom() | {atom(), node()}
  def farm_head(node \\ node())
  def farm_head(node) when node == node(), do: RingTracer.Farm.Head
  def farm_head(node), do: {RingTracer.Farm.Head, node}

  @doc "The head's supervisor of its jobs' runners."
  @spec farm_runners() :: atom()
  def farm_runners, do: RingTracer.Farm.Runners

  @doc "The supervisor of a farm's head (`RingTracer.Farm.start_head/1`)."
  @spec farm() :: atom()
  def farm, do: RingTracer.Farm.Supervisor

  @doc "A farm's dashboard, on the head node (`node` another one: the address to call)."
  @spec farm_dashboard(node()) :: atom() | {atom(), node()}
  def farm_dashboard(node \\ node())
  def farm_dashboard(node) when node == node(), do: RingTracer.Farm.Dashboard
  def farm_dashboard(node), do: {RingTracer.Farm.Dashboard, node}

  @doc "A worker's member of a farm (`RingTracer.Farm.join/2`)."
  @spec farm_member() :: atom()
  def farm_member, do: RingTracer.Farm.Member
end
