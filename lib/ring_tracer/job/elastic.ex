defmodule RingTracer.Job.Elastic do
  @moduledoc false
  # The pure rules of an elastic ring (`RingTracer.grow/4`): how many
  # children a running job may gain, and where children that join are
  # linked into the ring.
  #
  # Children are numbered on (a job of `n` children gains `n`, `n + 1`,
  # ...) and the ring stays in index order: a child's left sibling is the
  # living child with the next lower index, and the lowest one's is the
  # highest. So the children that join go after the highest living child,
  # and the lowest living child's left sibling becomes the highest of them.
  # An offer that goes past the end of the ring still goes to a higher index
  # (`RingTracer.Strategy.Ring.HelpOffer.hop/3`).

  @doc """
  Whether a job of `size` children may gain `count` more: at most
  #{RingTracer.Options.maxima().children} children in all.

      iex> RingTracer.Job.Elastic.check_size(4, 2)
      :ok
      iex> RingTracer.Job.Elastic.check_size(16_384, 1)
      {:error, "a job has at most 16384 children; it has 16384, and 1 more were asked for"}
  """
  @spec check_size(non_neg_integer(), pos_integer()) :: :ok | {:error, String.t()}
  def check_size(size, count) do
    max = RingTracer.Options.maxima().children

    if size + count <= max,
      do: :ok,
      else:
        {:error,
         "a job has at most #{max} children; it has #{size}, and #{count} more were asked for"}
  end

  @doc """
  The new left siblings when children `joined` (ascending, above every
  index in `living`) join a ring of the `living` children: one for each
  child that joined, and one for the lowest living child.

      iex> RingTracer.Job.Elastic.lefts([0, 2, 3], [5, 6])
      %{0 => 6, 5 => 3, 6 => 5}
      iex> RingTracer.Job.Elastic.lefts([0], [1])
      %{0 => 1, 1 => 0}
  """
  @spec lefts([non_neg_integer(), ...], [non_neg_integer(), ...]) ::
          %{non_neg_integer() => non_neg_integer()}
  def lefts(living, joined) do
    living = Enum.sort(living)
    ring = living ++ joined

    ring
    |> Enum.zip([List.last(ring) | Enum.drop(ring, -1)])
    |> Enum.filter(fn {i, _} -> i == hd(living) or i in joined end)
    |> Map.new()
  end
end
