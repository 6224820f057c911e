defmodule RingTracer.Report.OwnershipTest do
  use ExUnit.Case, async: true

  alias RingTracer.Report.{Ownership, Palette}

  @moduletag :tmp_dir

  setup_all do
    {:ok, result} =
      RingTracer.render(RingTracer.TestScenes.path("balls_s1.nff"),
        children: 4,
        atoms: 4,
        width: 32,
        height: 24,
        speeds: [1, 1, 4, 1]
      )

    %{result: result}
  end

  defp floats(bin), do: for(<<x::float-32-native <- bin>>, do: x)

  defp close?(a, b), do: Enum.zip(a, b) |> Enum.all?(fn {x, y} -> abs(x - y) < 1.0e-5 end)

  test "has the image's size and differs from it", %{result: result} do
    tinted = Ownership.pixels(result)
    assert byte_size(tinted) == result.width * result.height * 12
    assert tinted != result.pixels
  end

  test "each atom is tinted by the child that traced it, not its owner", %{result: result} do
    # Reassign atom 0 (child 0's strip) to child 2.
    atoms = Enum.map(result.atoms, &if(&1.atom == 0, do: %{&1 | child: 2}, else: &1))
    moved = %{result | atoms: atoms}
    layout = RingTracer.Layout.new(result.width, result.height, 4, 4)
    {first, count} = RingTracer.Layout.span(layout, 0)

    orig = floats(binary_part(result.pixels, first * 12, count * 12))
    before = floats(binary_part(Ownership.pixels(result), first * 12, count * 12))
    now = floats(binary_part(Ownership.pixels(moved), first * 12, count * 12))

    mix = fn {r, g, b} ->
      orig
      |> Enum.chunk_every(3)
      |> Enum.flat_map(fn [x, y, z] -> [(x + r) / 2, (y + g) / 2, (z + b) / 2] end)
    end

    # The unmoved result tints atom 0 with child 0; the moved one with child 2.
    assert close?(before, mix.(Palette.linear(0)))
    assert close?(now, mix.(Palette.linear(2)))
    refute close?(now, before)

    # Other atoms are untouched by the move.
    {f1, c1} = RingTracer.Layout.span(layout, 1)

    assert binary_part(Ownership.pixels(moved), f1 * 12, c1 * 12) ==
             binary_part(Ownership.pixels(result), f1 * 12, c1 * 12)
  end

  test "a black image becomes half the tracer's colour" do
    result = %RingTracer.Result{
      width: 4,
      height: 1,
      pixels: <<0::size(4 * 3 * 32)>>,
      elapsed_us: 10,
      rays: %{},
      settings: %RingTracer.Settings{width: 4, height: 1},
      children: [%{index: 0}, %{index: 1}],
      atoms: [
        %{atom: 0, owner: 0, child: 1, start_us: 0, end_us: 5, trace_us: 5},
        %{atom: 1, owner: 1, child: 1, start_us: 5, end_us: 10, trace_us: 5}
      ]
    }

    {r, g, b} = Palette.linear(1)

    assert close?(
             floats(Ownership.pixels(result)),
             List.duplicate([r / 2, g / 2, b / 2], 4) |> List.flatten()
           )
  end

  test "write/2 writes a PNG", %{result: result, tmp_dir: dir} do
    path = Path.join(dir, "owners.png")
    assert :ok = Ownership.write(result, path)
    assert <<137, "PNG", _::binary>> = File.read!(path)
  end

  test "a result in 8 bits needs its tinted image", %{result: result, tmp_dir: dir} do
    eight = %{result | pixels: RingTracer.Image.srgb8(result.pixels), pixel_format: :srgb8}
    path = Path.join(dir, "own.png")
    assert {:error, %RingTracer.Error{message: m}} = Ownership.write(eight, path)
    assert m =~ "ownership: true"
    refute File.exists?(path)
  end
end
