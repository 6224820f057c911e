defmodule RingTracer.LayoutTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Layout

  alias RingTracer.Layout

  test "strips are the children's atoms, contiguous and in order" do
    layout = Layout.new(7, 5, 3, 4)
    assert Enum.flat_map(0..2, &Layout.strip(layout, &1)) == Enum.to_list(Layout.atoms(layout))

    assert Enum.map(Layout.atoms(layout), &Layout.owner(layout, &1)) ==
             List.flatten(for i <- 0..2, do: List.duplicate(i, 4))
  end

  test "interleaved strips: child i owns atoms i, i + n, ...; every atom once, owner agrees" do
    for {n, k} <- [{3, 4}, {1, 5}, {8, 16}, {5, 1}] do
      layout = Layout.new(40, 30, n, k, :interleaved)
      strips = for i <- 0..(n - 1), do: Layout.strip(layout, i)

      assert Enum.sort(List.flatten(strips)) == Enum.to_list(Layout.atoms(layout))
      assert Enum.all?(strips, &(length(&1) == k))

      for {strip, i} <- Enum.with_index(strips), a <- strip do
        assert Layout.owner(layout, a) == i
        assert rem(a, n) == i
      end
    end

    # The atoms themselves do not depend on the order.
    spans = fn order ->
      layout = Layout.new(7, 5, 3, 4, order)
      Enum.map(Layout.atoms(layout), &Layout.span(layout, &1))
    end

    assert spans.(:interleaved) == spans.(:strips)
  end

  test "more atoms than pixels leaves some atoms empty but still tiles the image" do
    layout = Layout.new(2, 1, 3, 2)
    spans = Enum.map(Layout.atoms(layout), &Layout.span(layout, &1))
    assert Enum.sum(Enum.map(spans, &elem(&1, 1))) == 2
    assert Enum.count(spans, &(elem(&1, 1) == 0)) == 4
  end

  test "property: atoms tile every pixel exactly once, in order, for any size" do
    gen =
      {:proper_types.integer(1, 300), :proper_types.integer(1, 300), :proper_types.integer(1, 40),
       :proper_types.integer(1, 70)}

    RingTracer.PropErCase.check(
      gen,
      fn {w, h, n, k} ->
        layout = Layout.new(w, h, n, k)

        {next, ok} =
          Enum.reduce(Layout.atoms(layout), {0, true}, fn a, {expected, ok} ->
            {first, count} = Layout.span(layout, a)
            {first + count, ok and first == expected and count >= 0}
          end)

        ok and next == w * h
      end,
      300
    )
  end
end
