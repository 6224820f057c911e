defmodule RingTracer.PropErCase do
  @moduledoc """
  Runs PropEr (Debian's `erlang-proper`) properties from ExUnit.

  `check(generator, fun, numtests)` fails the test with the shrunk
  counterexample when the property does not hold.
  """
  import ExUnit.Assertions

  @doc "Checks that `fun` returns true for every value `gen` generates."
  @spec check(term(), (term() -> boolean()), pos_integer()) :: true
  def check(gen, fun, numtests) do
    property = :proper.forall(gen, fun)

    case :proper.quickcheck(property, [:quiet, {:numtests, numtests}]) do
      true ->
        true

      other ->
        flunk(
          "property failed: #{inspect(other)}; counterexample: #{inspect(:proper.counterexample())}"
        )
    end
  end
end
