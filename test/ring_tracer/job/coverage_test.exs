defmodule RingTracer.Job.CoverageTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Job.Coverage

  alias RingTracer.Job.{Coverage, Parent}
  alias RingTracer.Layout

  # Cuts atom `a` at random, again and again; returns its pieces in order.
  defp cut(pieces, 0), do: pieces

  defp cut(pieces, n) do
    i = :rand.uniform(length(pieces)) - 1
    d = Enum.random(2..9)
    {h, t} = Layout.split(Enum.at(pieces, i), Enum.random(1..(d - 1)), d)
    pieces |> List.replace_at(i, [h, t]) |> List.flatten() |> cut(n - 1)
  end

  test "random cuts tile an atom exactly: complete only once every piece is in, and assembled in order" do
    layout = Layout.new(97, 3, 2, 2)
    :rand.seed(:exsss, {1, 2, 3})

    for _ <- 1..50, a <- Layout.atoms(layout) do
      pieces = cut([a], Enum.random(0..6))
      spans = Enum.map(pieces, &Layout.span(layout, &1))
      {first, count} = Layout.span(layout, a)
      assert Enum.sum(Enum.map(spans, &elem(&1, 1))) == count
      assert hd(spans) |> elem(0) == first

      Enum.chunk_every(spans, 2, 1, :discard)
      |> Enum.each(fn [{f, c}, {g, _}] -> assert f + c == g end)

      {coverage, _} =
        pieces
        |> Enum.shuffle()
        |> Enum.reduce({Coverage.new(), length(pieces)}, fn p, {cov, left} ->
          refute Coverage.complete?(cov, a)
          assert {:new, cov} = Coverage.add(cov, p)
          assert {:duplicate, ^cov} = Coverage.add(cov, p)
          {cov, left - 1}
        end)

      assert Coverage.complete?(coverage, a)
      assert {:duplicate, _} = Coverage.add(coverage, a)
    end
  end

  test "assemble/2 gives each pixel once from pieces that overlap" do
    layout = Layout.new(10, 1, 1, 1)
    pixel = fn i -> <<i::96>> end

    piece = fn p ->
      {f, c} = Layout.span(layout, p)
      for(i <- f..(f + c - 1)//1, into: <<>>, do: pixel.(i))
    end

    whole = piece.(0)
    pieces = [{0, 0, 1, 3}, {0, 1, 3, 5}, {0, 1, 2, 2}, {0, 2, 3, 3}]
    assert Parent.assemble(layout, Map.new(pieces, &{&1, piece.(&1)})) == whole
  end
end
