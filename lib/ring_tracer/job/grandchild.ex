defmodule RingTracer.Job.Grandchild do
  @moduledoc """
  A grandchild: spawned and linked by a child on the child's node, it traces
  one atom at a time through the NIF (on a dirty CPU scheduler) and sends the
  atom's pixels back to its child.

  Its mailbox is the paper's pipe: the child keeps the next atom queued in it,
  so the grandchild never waits while its child still has atoms.

  Messages in: `{:trace, atom}`. Messages out, to the child:
  `{:traced, self(), atom, pixels, rays, microseconds}` or
  `{:atom_failed, self(), atom, message}` when the kernel returns an error or
  raises.
  """

  alias RingTracer.{Layout, Native, Settings}

  @doc "Spawns a grandchild linked to the calling child."
  @spec start_link(reference(), Settings.t(), Layout.t()) :: pid()
  def start_link(scene_ref, %Settings{} = settings, %Layout{} = layout) do
    child = self()
    native = Settings.to_native(settings)
    spawn_link(fn -> loop(child, scene_ref, native, layout) end)
  end

  defp loop(child, scene_ref, native, layout) do
    receive do
      {:trace, atom} ->
        send(child, trace(scene_ref, native, layout, atom))
        loop(child, scene_ref, native, layout)
    end
  end

  @doc false
  @spec trace(reference(), map(), Layout.t(), non_neg_integer()) :: tuple()
  def trace(scene_ref, native, layout, atom) do
    {first, count} = Layout.span(layout, atom)
    t0 = System.monotonic_time(:microsecond)

    result =
      try do
        Native.trace_atom(scene_ref, native, first, count)
      rescue
        e -> {:error, Exception.message(e)}
      end

    us = System.monotonic_time(:microsecond) - t0

    case result do
      {:ok, {pixels, rays}} -> {:traced, self(), atom, pixels, rays, us}
      {:error, message} -> {:atom_failed, self(), atom, message}
    end
  end
end
