defmodule RingTracer.ImageTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Image

  alias RingTracer.Image

  @tag :tmp_dir
  test "PNG and EXR files are written by extension", %{tmp_dir: dir} do
    pixels = for v <- [0.0, 0.5, 1.0, 2.0, 0.25, 0.0], into: <<>>, do: <<v::float-32-native>>
    assert :ok = Image.write(Path.join(dir, "a.png"), 2, 1, pixels)
    assert <<137, "PNG", _::binary>> = File.read!(Path.join(dir, "a.png"))
    assert :ok = Image.write(Path.join(dir, "a.exr"), 2, 1, pixels)
    assert <<0x76, 0x2F, 0x31, 0x01, _::binary>> = File.read!(Path.join(dir, "a.exr"))
  end

  test "sRGB encoding of linear values" do
    pixels = for v <- [0.0, 1.0, 2.0, 0.5], into: <<>>, do: <<v::float-32-native>>
    assert <<0, 255, 255, 188>> = Image.srgb8(pixels)
  end

  @tag :tmp_dir
  test "unknown extensions and wrong sizes are errors", %{tmp_dir: dir} do
    assert {:error, %RingTracer.Error{message: m}} =
             Image.write(Path.join(dir, "a.jpg"), 1, 1, <<0::96>>)

    assert m =~ "a.jpg"
    assert {:error, %RingTracer.Error{}} = Image.write(Path.join(dir, "b.png"), 2, 2, <<0::96>>)
  end

  @tag :tmp_dir
  test "8-bit pixels make the PNG of the floats they came from; not an EXR", %{tmp_dir: dir} do
    floats =
      for i <- 1..(7 * 5 * 3), into: <<>>, do: <<:math.sin(i * 0.7) * 1.2::float-32-native>>

    bytes = Image.srgb8(floats)
    assert Image.png(7, 5, bytes, :srgb8) == Image.png(7, 5, floats)
    assert :ok = Image.write(Path.join(dir, "a.png"), 7, 5, floats)
    assert :ok = Image.write(Path.join(dir, "b.png"), 7, 5, bytes, format: :srgb8)
    assert File.read!(Path.join(dir, "a.png")) == File.read!(Path.join(dir, "b.png"))

    {:ok, held} = RingTracer.Output.open_dir(dir)
    assert :ok = Image.write(Path.join(dir, "c.png"), 7, 5, bytes, format: :srgb8, in: held)
    assert File.read!(Path.join(dir, "c.png")) == File.read!(Path.join(dir, "a.png"))

    assert {:error, %RingTracer.Error{reason: :file, message: m}} =
             Image.write(Path.join(dir, "a.exr"), 7, 5, bytes, format: :srgb8)

    assert m =~ "a.exr" and m =~ ".png only"
    refute File.exists?(Path.join(dir, "a.exr"))
    assert {:error, %RingTracer.Error{}} = Image.png(7, 5, binary_part(bytes, 0, 9), :srgb8)

    assert {:error, %RingTracer.Error{}} =
             Image.write(Path.join(dir, "d.png"), 7, 5, <<1, 2, 3>>, format: :srgb8)
  end
end
