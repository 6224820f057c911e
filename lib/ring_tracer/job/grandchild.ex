defmodule RingTracer.Job.Grandchild do
  @moduledoc """
  A grandchild: spawned and linked by a child on the child's node, it traces
  one atom at a time through the job's kernel (`RingTracer.Kernel`; the
  native one runs on a dirty CPU scheduler) and sends the atom's pixels back
  to its child.

  Its mailbox is the paper's pipe: the child keeps the next atom queued in it,
  so the grandchild never waits while its child still has atoms.

  A child with speed factor `s > 1` emulates a machine `s` times slower: after
  each atom its grandchild sleeps `(s - 1)` times the atom's trace time,
  burning no CPU.

  Before tracing an atom it claims it (`RingTracer.Job.Pipe`): the child
  may have taken the queued atom back to hand it to a sibling, and then the
  grandchild skips it.

  Messages in: `{:trace, atom}`. Messages out, to the child:
  `{:traced, self(), atom, pixels, rays, timing}` (timing: `:trace_us`,
  `:started_at`, `:ended_at` in system microseconds) or
  `{:atom_failed, self(), atom, message}`.
  """

  alias RingTracer.Job.{Pipe, Slowdown}
  alias RingTracer.Layout

  @doc "Spawns a grandchild linked to the calling child."
  @spec start_link({module(), term()}, Layout.t(), number()) :: pid()
  def start_link(kernel, %Layout{} = layout, speed) do
    child = self()
    spawn_link(fn -> loop(child, kernel, layout, Slowdown.new(speed)) end)
  end

  defp loop(child, kernel, layout, slowdown) do
    receive do
      {:trace, atom} ->
        # The child may have taken the atom back for a sibling (`Pipe`).
        slowdown =
          if Pipe.claim(self(), atom) do
            {message, slowdown} = trace(kernel, layout, slowdown, atom)
            send(child, message)
            slowdown
          else
            slowdown
          end

        loop(child, kernel, layout, slowdown)
    end
  end

  defp trace({kernel, context}, layout, slowdown, atom) do
    {first, count} = Layout.span(layout, atom)
    started = System.system_time(:microsecond)

    case kernel.trace(context, first, count, atom) do
      {:ok, pixels, rays, us} ->
        slowdown = Slowdown.wait(slowdown, us)
        timing = %{trace_us: us, started_at: started, ended_at: System.system_time(:microsecond)}
        {{:traced, self(), atom, pixels, rays, timing}, slowdown}

      {:error, message} ->
        {{:atom_failed, self(), atom, message}, slowdown}
    end
  end
end
