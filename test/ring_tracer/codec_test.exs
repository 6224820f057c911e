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
      frame = Codec.compress(bytes)
      assert {:ok, ^bytes} = Codec.decompress(frame, byte_size(bytes))
    end

    assert byte_size(Codec.compress(:binary.copy("ab", 500_000))) < 1000
  end

  test "more than the bound, or corrupt frames, are errors, not crashes" do
    frame = Codec.compress(:binary.copy("x", 10_000))
    assert {:error, message} = Codec.decompress(frame, 9_999)
    assert message =~ "more than 9999 bytes"

    for bad <- [
          binary_part(frame, 0, byte_size(frame) - 3),
          "not zstd at all",
          <<40, 181, 47, 253>>
        ] do
      assert {:error, message} = Codec.decompress(bad, 10_000)
      assert message =~ "corrupt"
    end
  end
end
