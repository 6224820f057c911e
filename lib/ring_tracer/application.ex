defmodule RingTracer.Application do
  @moduledoc false
  use Application

  alias RingTracer.Names

  @impl Application
  def start(_type, _args) do
    children = [
      RingTracer.Telemetry,
      RingTracer.SceneCache,
      RingTracer.Job.Pipe,
      RingTracer.Job.Directory,
      {DynamicSupervisor, name: Names.jobs(), strategy: :one_for_one},
      {DynamicSupervisor, name: Names.children(), strategy: :one_for_one},
      %{id: :pg, start: {:pg, :start_link, [RingTracer.Cluster.scope()]}},
      RingTracer.Cluster
    ]

    Supervisor.start_link(children, strategy: :one_for_one, name: RingTracer.Supervisor)
  end
end
