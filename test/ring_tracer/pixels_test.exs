defmodule RingTracer.PixelsTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Pixels

  alias RingTracer.{Image, Pixels, TestScenes}
  alias RingTracer.Report.{Ownership, Palette}

  # Floats of every kind a kernel may give: in range, above 1, negative,
  # tiny, and random bit patterns (NaNs and infinities among them).
  defp floats(n) do
    :rand.seed(:exsss, {1, 2, 3})
    values = [0.0, 1.0, 0.5, 2.5, -0.25, 1.0e-30, 0.2140, 0.2142]

    for i <- 1..(n * 3)//1, into: <<>> do
      case rem(i, 3) do
        0 -> <<:rand.uniform(0xFFFFFFFF)::32-native>>
        _ -> <<Enum.random(values) * :rand.uniform()::float-32-native>>
      end
    end
  end

  describe "the wire" do
    test ":float gives back the exact bytes" do
      for n <- [0, 1, 7, 4096, 30_000] do
        floats = floats(n)
        assert {:ok, wire} = Pixels.encode(floats, :float)
        assert {:ok, ^floats} = Pixels.decode(wire, :float, n)
      end
    end

    test ":srgb8 gives the PNG writer's 8-bit bytes" do
      for n <- [1, 5000, 30_000] do
        floats = floats(n)
        assert {:ok, wire} = Pixels.encode(floats, :srgb8)
        assert {:ok, bytes} = Pixels.decode(wire, :srgb8, n)
        assert bytes == Image.srgb8(floats)
        assert byte_size(bytes) == Pixels.size(n, :srgb8)
      end
    end

    test "the tint is the ownership map's, to the byte" do
      :rand.seed(:exsss, {4, 5, 6})
      floats = for _ <- 1..6000, into: <<>>, do: <<:rand.uniform() * 1.5 - 0.2::float-32-native>>

      for i <- [0, 3, 7] do
        {cr, cg, cb} = colour = Palette.linear(i)
        assert {:ok, wire} = Pixels.encode_tinted(floats, colour)
        assert {:ok, tinted} = Pixels.decode(wire, :srgb8, 2000)

        mixed =
          for <<r::float-32-native, g::float-32-native, b::float-32-native <- floats>>,
            into: <<>> do
            <<(r + cr) / 2::float-32-native, (g + cg) / 2::float-32-native,
              (b + cb) / 2::float-32-native>>
          end

        assert tinted == Image.srgb8(mixed)
      end
    end

    test "corrupt, short or mismatched input is an error, not a crash" do
      floats = floats(300)
      {:ok, wire} = Pixels.encode(floats, :float)
      {:ok, eight} = Pixels.encode(floats, :srgb8)
      <<tag, frame::binary>> = wire

      for {bad, format, count} <- [
            {wire, :float, 299},
            {wire, :float, 301},
            {wire, :srgb8, 1200},
            {eight, :float, 300},
            {binary_part(wire, 0, div(byte_size(wire), 2)), :float, 300},
            {<<tag, :binary.copy(<<0xAB>>, byte_size(frame))::binary>>, :float, 300},
            {<<>>, :float, 0},
            {<<9, frame::binary>>, :float, 300},
            {floats, :float, 300},
            {:not_a_binary, :float, 300}
          ] do
        assert {:error, message} = Pixels.decode(bad, format, count)
        assert is_binary(message) and message != ""
      end

      assert {:error, message} = Pixels.encode(binary_part(floats, 0, 20), :float)
      assert message =~ "not whole"
      assert {:error, _} = Pixels.encode(binary_part(floats, 0, 22), :srgb8)
    end

    test "bytes per pixel and slices" do
      assert Pixels.size(10, :float) == 120
      assert Pixels.size(10, :srgb8) == 30
      assert Pixels.slice("abcdefghijkl", :srgb8, 1, 2) == "defghi"
      assert Pixels.count("abcdefg", :srgb8) == 2
    end
  end

  describe "renders" do
    @describetag :tmp_dir

    defp render(scene, opts) do
      {:ok, result} =
        RingTracer.render(TestScenes.path(scene), Keyword.merge([width: 48, height: 40], opts))

      result
    end

    test "PNGs and ownership maps are byte-identical in :float and :srgb8", %{tmp_dir: dir} do
      for scene <- ["balls_s1.nff", "tetra_s3.nff", "whitted.toml"] do
        opts = [children: 3, atoms: 4, speeds: [1, 3]]
        float = render(scene, opts)
        eight = render(scene, [pixels: :srgb8, ownership: true] ++ opts)

        assert float.pixel_format == :float and float.tinted == nil
        assert eight.pixel_format == :srgb8
        assert byte_size(eight.pixels) == 48 * 40 * 3
        assert eight.pixels == Image.srgb8(float.pixels)
        assert Image.to_png(float) == Image.to_png(eight)

        # Who traced what differs from run to run: the ownership map of the
        # 8-bit job against the map of its own atoms over the floats.
        as_float = %{eight | pixels: float.pixels, pixel_format: :float, tinted: nil}

        for {name, result, map} <- [{"f", float, as_float}, {"e", eight, eight}] do
          :ok = Image.write(result, Path.join(dir, "#{name}.png"))
          :ok = Ownership.write(map, Path.join(dir, "#{name}_own.png"))
        end

        read = &File.read!(Path.join(dir, &1))
        assert read.("f.png") == read.("e.png"), scene
        assert read.("f_own.png") == read.("e_own.png"), scene
        assert read.("f_own.png") != read.("f.png")
      end
    end

    test "atoms cut into pieces assemble the same image in :srgb8" do
      reference = Image.srgb8(TestScenes.reference("balls_s2.nff", 64, 48))

      strategy =
        {RingTracer.Strategy.Ring, [split: true, part_us: 0, part_rows: 0, cut_faster: 0.0]}

      # pieces come when offers reach slow children mid-atom: try a few times
      pieces =
        Enum.reduce_while(1..20, 0, fn _, _ ->
          {:ok, r} =
            RingTracer.render(TestScenes.path("balls_s2.nff"),
              width: 64,
              height: 48,
              children: 3,
              atoms: 4,
              speeds: [1, 6, 1],
              strategy: strategy,
              pixels: :srgb8
            )

          assert r.pixels == reference
          pieces = Enum.count(r.atoms, &(not is_integer(&1.atom)))
          if pieces > 0, do: {:halt, pieces}, else: {:cont, 0}
        end)

      assert pieces > 0
    end

    test "an :srgb8 job sends at most 3.5 bytes a pixel; :float is lossless" do
      opts = [width: 96, height: 80, children: 2, atoms: 4]
      eight = render("balls_s2.nff", [pixels: :srgb8] ++ opts)
      float = render("balls_s2.nff", opts)

      assert eight.messages.result.bytes / (96 * 80) <= 3.5
      assert float.messages.result.bytes < 96 * 80 * 12
      assert float.pixels == TestScenes.reference("balls_s2.nff", 96, 80)
    end

    test "an EXR of 8-bit pixels is a clear error", %{tmp_dir: dir} do
      eight = render("tetra_s1.nff", children: 2, atoms: 2, pixels: :srgb8)
      path = Path.join(dir, "a.exr")

      assert {:error, %RingTracer.Error{reason: :file, message: message}} =
               Image.write(eight, path)

      assert message =~ ".png only"
      refute File.exists?(path)
    end
  end
end
