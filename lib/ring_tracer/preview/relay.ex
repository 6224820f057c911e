defmodule RingTracer.Preview.Relay do
  @moduledoc false
  # `RingTracer.Telemetry` handlers of a preview (functions of a module, so
  # that one can be attached on another node, where children run): each
  # sends one message to the preview's server and returns. The server
  # filters by job.

  @doc false
  def atom(_event, m, md, server),
    do:
      send(
        server,
        {:atom, md.job, md.atom, md.child, md.pixels, m.rays, m.trace_us,
         System.system_time(:microsecond)}
      )

  @doc false
  def moved(_event, m, md, server),
    do: send(server, {:moved, md.job, md.from, md.to, m.atoms, System.system_time(:microsecond)})

  @doc false
  def frame_start(_event, m, md, server),
    do: send(server, {:frame_start, md.job, md.frame, m.at_us})

  @doc false
  # The frame's pixels are a reference-counted binary: not copied.
  def frame_stop(_event, m, md, server),
    do: send(server, {:frame_stop, md.job, md.frame, m.at_us, m.elapsed_us})

  @doc false
  # Also raises the flag that ends the preview's pacing at once (its
  # message may queue behind atoms).
  # Run by the job's parent: its description, in case the server runs only
  # after the parent has ended.
  def job_start(_event, _m, md, server),
    do: send(server, {:job_start, self(), md.job, md.description})

  @doc false
  def job_stop(_event, _m, md, {server, ended}) do
    :atomics.put(ended, 1, 1)
    send(server, {:job_stop, md.job, md.reply})
  end

  # On a child's node: only that job's events cross the network.
  @doc false
  def child_event(_event, m, md, {server, job}) do
    if job == nil or md.job == job,
      do: send(server, {:child_event, md.job, md.kind, md.from, md.to, m.at_us})
  end
end
