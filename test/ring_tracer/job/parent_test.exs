defmodule RingTracer.Job.ParentTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Parent

  alias RingTracer.Job.Parent

  test "property: shares hand out every atom once, in order, each within one of its proportion" do
    import :proper_types

    gen = {integer(0, 200), non_empty(list(integer(1, 50)))}

    RingTracer.PropErCase.check(
      gen,
      fn {n, ws} ->
        weights = Enum.with_index(ws, fn w, i -> {i, w} end)
        shares = Parent.shares(Enum.to_list(1..n//1), weights)
        total = Enum.sum(ws)

        Enum.flat_map(shares, &elem(&1, 1)) == Enum.to_list(1..n//1) and
          Enum.all?(weights, fn {i, w} ->
            got = shares |> List.keyfind(i, 0, {i, []}) |> elem(1) |> length()
            abs(got - n * w / total) < 1
          end)
      end,
      500
    )
  end

  test "an atom that comes back with the wrong number of pixels fails the job, in either format" do
    for format <- [:float, :srgb8] do
      assert {:error, %RingTracer.Error{reason: :render_failed, message: message}} =
               RingTracer.render(RingTracer.TestScenes.path("tetra_s1.nff"),
                 width: 16,
                 height: 16,
                 children: 2,
                 atoms: 2,
                 pixels: format,
                 kernel: {RingTracer.Test.FaultyKernel, short_pixel: 70}
               )

      size = RingTracer.Pixels.size(64, format)
      assert message =~ "atom 1 came back with"
      assert message =~ "not its 64 pixels (#{size} bytes of #{format})"
    end
  end
end
