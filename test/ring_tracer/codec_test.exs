defmodule RingTracer.CodecTest do
  use ExUnit.Case, async: true

  alias RingTracer.Codec

  test "bytes come back as they were, within the bound" do
    for bytes <- [
          <<>>,
          "a scene",
          :crypto.strong_rand_bytes(100_000),
          :binary.copy("ab", 500_000)
        ] do
      assert {:ok, frame} = Codec.compress(bytes)
      assert {:ok, ^bytes} = Codec.decompress(frame, byte_size(bytes))
    end

    {:ok, frame} = Codec.compress(:binary.copy("ab", 500_000))
    assert byte_size(frame) < 1000
  end

  test "more than the bound, or corrupt frames, are errors, not crashes" do
    {:ok, frame} = Codec.compress(:binary.copy("x", 10_000))

    assert {:error, %RingTracer.Error{reason: :corrupt, message: m}} =
             Codec.decompress(frame, 9_999)

    assert m =~ "more than 9999 bytes"

    for bad <- [
          binary_part(frame, 0, byte_size(frame) - 3),
          "not zstd at all",
          <<40, 181, 47, 253>>
        ] do
      assert {:error, %RingTracer.Error{reason: :corrupt}} = Codec.decompress(bad, 10_000)
    end
  end
end
