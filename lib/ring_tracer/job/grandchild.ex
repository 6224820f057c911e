defmodule RingTracer.Job.Grandchild do
  @moduledoc false
  # A grandchild: spawned and linked by a child on the child's node, it traces
  # one atom at a time through the job's kernel (`RingTracer.Kernel`; the
  # native one runs on a dirty CPU scheduler) and sends the atom's pixels back
  # to its child.
  #
  # Its mailbox is the paper's pipe: the child keeps the next atom queued in it,
  # so the grandchild never waits while its child still has atoms.
  #
  # A child with speed factor `s > 1` emulates a machine `s` times slower: after
  # each atom its grandchild sleeps `(s - 1)` times the atom's trace time,
  # burning no CPU.
  #
  # Before tracing an atom it claims it (`RingTracer.Job.Pipe`): the child
  # may have taken the queued atom back to hand it to a sibling, and then the
  # grandchild skips it.
  #
  # A long atom may be traced in parts (`{:trace, atom, n}`: `n` kernel calls,
  # each followed by its slowdown), so that its child can cut off the parts
  # not yet started for a faster sibling (`RingTracer.Job.Pipe.cut/3`); the
  # parts traced come back as one piece (`RingTracer.Layout.parts/4`).
  #
  # The pixels go out encoded for the wire in the job's format
  # (`RingTracer.Pixels.encode/2`); with a tint (the ownership map of a job
  # in `:srgb8`), with the pixels mixed with the child's colour beside them
  # (`RingTracer.Pixels.encode_tinted/2`).
  #
  # Messages in: `{:trace, atom}`, `{:trace, atom, n}`. Messages out, to the child:
  # `{:traced, self(), atom, pixels, rays, timing}` (pixels: `t:sent/0`;
  # timing: `:trace_us`, `:started_at`, `:ended_at` in system microseconds) or
  # `{:atom_failed, self(), atom, message}`.

  alias RingTracer.Job.{Pipe, Slowdown}
  alias RingTracer.{Layout, Pixels, Rays}

  @typedoc """
  How traced pixels go out: in `format`, and with `tint` (a linear colour)
  also tinted for the ownership map.
  """
  @type wire :: %{format: Pixels.format(), tint: {float(), float(), float()} | nil}

  @typedoc "An atom's pixels as sent: on the wire, and tinted beside them with a `tint`."
  @type sent :: Pixels.wire() | {Pixels.wire(), Pixels.wire()}

  @doc "Spawns a grandchild linked to the calling child."
  @spec start_link({module(), term()}, Layout.t(), number(), wire()) :: pid()
  def start_link(kernel, %Layout{} = layout, speed, wire \\ %{format: :float, tint: nil}) do
    child = self()
    spawn_link(fn -> loop(child, {kernel, wire}, layout, Slowdown.new(speed)) end)
  end

  # `tracer`: the kernel, and how its pixels go out (`t:wire/0`).
  defp loop(child, tracer, layout, slowdown) do
    receive do
      {:trace, atom} ->
        loop(child, tracer, layout, take(child, tracer, layout, slowdown, atom, 1))

      {:trace, atom, n} ->
        loop(child, tracer, layout, take(child, tracer, layout, slowdown, atom, n))
    end
  end

  # The child may have taken the atom back for a sibling (`Pipe`).
  defp take(child, {kernel, wire}, layout, slowdown, atom, n) do
    if Pipe.claim(self(), atom) do
      {message, slowdown} = trace(kernel, layout, slowdown, atom, n)
      message = encoded(message, wire)
      send(child, message)
      slowdown
    else
      slowdown
    end
  end

  # Traces `atom` in `n` parts, one kernel call each, taking each part after
  # the first from the pipe (`Pipe.next/2`): the child may cut the rest off
  # for a sibling. Pixels, counters and times add up over the parts traced,
  # which are reported as one atom or piece.
  defp trace(kernel, layout, slowdown, atom, n) do
    started = System.system_time(:microsecond)
    acc = %{pixels: [], rays: Rays.zero(), us: 0, slowdown: slowdown}

    case parts(kernel, layout, atom, n, 0, acc) do
      {:ok, done, acc} ->
        traced = if done == n, do: atom, else: Layout.parts(atom, 0, done, n)

        timing = %{
          trace_us: acc.us,
          started_at: started,
          ended_at: System.system_time(:microsecond)
        }

        pixels = IO.iodata_to_binary(Enum.reverse(acc.pixels))
        {{:traced, self(), traced, pixels, acc.rays, timing}, acc.slowdown}

      {:error, message, acc} ->
        # An earlier cut left us only its first parts: they are what failed.
        failed =
          case n > 1 && Pipe.fail(self(), atom) do
            kept when is_integer(kept) -> Layout.parts(atom, 0, kept, n)
            _ -> atom
          end

        {{:atom_failed, self(), failed, message}, acc.slowdown}
    end
  end

  defp encoded({:traced, gc, atom, pixels, rays, timing}, wire) do
    with {:ok, sent} <- Pixels.encode(pixels, wire.format),
         {:ok, sent} <- tinted(sent, pixels, wire.tint) do
      {:traced, gc, atom, sent, rays, timing}
    else
      {:error, message} -> {:atom_failed, gc, atom, "its pixels could not be encoded: #{message}"}
    end
  end

  defp encoded(failed, _wire), do: failed

  defp tinted(sent, _pixels, nil), do: {:ok, sent}

  defp tinted(sent, pixels, colour) do
    with {:ok, tinted} <- Pixels.encode_tinted(pixels, colour), do: {:ok, {sent, tinted}}
  end

  defp parts(_kernel, _layout, _atom, n, n, acc), do: {:ok, n, acc}

  defp parts(kernel, layout, atom, n, i, acc) do
    if i == 0 or Pipe.next(self(), atom) do
      part = if n == 1, do: atom, else: Layout.parts(atom, i, i + 1, n)

      case trace_one(kernel, layout, acc.slowdown, part) do
        {:ok, pixels, rays, us, slowdown} ->
          acc = %{
            acc
            | pixels: [pixels | acc.pixels],
              rays: if(i == 0, do: rays, else: Rays.add(acc.rays, rays)),
              us: acc.us + us,
              slowdown: slowdown
          }

          parts(kernel, layout, atom, n, i + 1, acc)

        {:error, message} ->
          {:error, message, acc}
      end
    else
      {:ok, i, acc}
    end
  end

  defp trace_one({kernel, context}, layout, slowdown, atom) do
    {first, count} = Layout.span(layout, atom)

    case kernel.trace(context, first, count, atom) do
      {:ok, pixels, rays, us} -> {:ok, pixels, rays, us, Slowdown.wait(slowdown, us)}
      {:error, message} -> {:error, message}
    end
  end
end
