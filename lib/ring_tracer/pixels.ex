defmodule RingTracer.Pixels do
  @moduledoc false
  # The one home of pixel formats: what a job's `:pixels` may be, how many
  # bytes a pixel takes, and an atom's pixels on the wire, from the
  # grandchild that traced them to the job's parent (docs/protocol.md,
  # "Pixels on the wire"):
  #
  #   * `:float` — linear RGB, native-endian f32 triples (12 bytes a pixel),
  #     what the kernel traces; sent losslessly compressed;
  #   * `:srgb8` — 8-bit sRGB (3 bytes a pixel), the PNG writer's
  #     conversion of those floats: a PNG of them is byte for byte the PNG
  #     of the floats; sent compressed.
  #
  # Encoding and decoding run in the NIF, on a normal scheduler for the many
  # small atoms (a 4,096-pixel atom: 70 us to encode in floats, 50 us in 8
  # bits, less to decode), where a switch to a dirty scheduler would cost
  # about as much; past `@dirty_bytes` of floats (5,461 pixels, some 0.15 ms)
  # on a dirty CPU one, so that no normal scheduler is held long.

  alias RingTracer.Native

  @type format :: :float | :srgb8

  @typedoc "An atom's pixels as a grandchild sends them (`encode/2`)."
  @type wire :: binary()

  @formats [:float, :srgb8]
  @dirty_bytes 64 * 1024

  @doc "The pixel formats, the default first."
  @spec formats() :: [format(), ...]
  def formats, do: @formats

  @doc """
  Bytes a pixel takes in `format`.

      iex> RingTracer.Pixels.bytes_per_pixel(:float)
      12
      iex> RingTracer.Pixels.bytes_per_pixel(:srgb8)
      3
  """
  @spec bytes_per_pixel(format()) :: pos_integer()
  def bytes_per_pixel(:float), do: 12
  def bytes_per_pixel(:srgb8), do: 3

  @doc """
  The format a job writing the images `paths` needs: `:srgb8` when every
  one is a PNG (8-bit: the job need not send more), else `:float`.

      iex> RingTracer.Pixels.for_files(["a.png", "frames/f_####.PNG"])
      :srgb8
      iex> RingTracer.Pixels.for_files(["a.png", "b.exr"])
      :float
      iex> RingTracer.Pixels.for_files([])
      :float
  """
  @spec for_files([Path.t()]) :: format()
  def for_files([_ | _] = paths) do
    if Enum.all?(paths, &(String.downcase(Path.extname(&1)) == ".png")),
      do: :srgb8,
      else: :float
  end

  def for_files([]), do: :float

  @doc "Bytes of `count` pixels in `format`."
  @spec size(non_neg_integer(), format()) :: non_neg_integer()
  def size(count, format), do: count * bytes_per_pixel(format)

  @doc "How many pixels `pixels` in `format` are (a partial pixel does not count)."
  @spec count(binary(), format()) :: non_neg_integer()
  def count(pixels, format), do: div(byte_size(pixels), bytes_per_pixel(format))

  @doc "Pixels `first` to `first + count - 1` of `pixels` in `format`."
  @spec slice(binary(), format(), non_neg_integer(), non_neg_integer()) :: binary()
  def slice(pixels, format, first, count) do
    bpp = bytes_per_pixel(format)
    binary_part(pixels, first * bpp, count * bpp)
  end

  @doc """
  Linear f32 RGB `floats` (as a kernel traces them) on the wire in
  `format`: `decode/3` gives back the floats themselves (`:float`) or
  their 8-bit sRGB bytes (`:srgb8`).
  """
  @spec encode(binary(), format()) :: {:ok, wire()} | {:error, String.t()}
  def encode(floats, format) when format in @formats do
    if byte_size(floats) > @dirty_bytes,
      do: Native.pixels_encode_dirty(floats, format),
      else: Native.pixels_encode(floats, format)
  end

  @doc """
  Linear f32 RGB `floats` mixed 50/50 in linear light with `colour`
  (`RingTracer.Report.Palette.linear/1`), as `RingTracer.Report.Ownership`
  tints, on the wire as `:srgb8`.
  """
  @spec encode_tinted(binary(), {float(), float(), float()}) ::
          {:ok, wire()} | {:error, String.t()}
  def encode_tinted(floats, {r, g, b} = colour)
      when is_float(r) and is_float(g) and is_float(b) do
    if byte_size(floats) > @dirty_bytes,
      do: Native.pixels_tint_dirty(floats, colour),
      else: Native.pixels_tint(floats, colour)
  end

  @doc """
  The `count` pixels in `format` that `wire` holds. Input of another
  format or size, or corrupt, is an error naming the problem.
  """
  @spec decode(wire(), format(), non_neg_integer()) :: {:ok, binary()} | {:error, String.t()}
  def decode(wire, format, count)
      when is_binary(wire) and format in @formats and is_integer(count) and count >= 0 do
    if size(count, :float) > @dirty_bytes,
      do: Native.pixels_decode_dirty(wire, format, count),
      else: Native.pixels_decode(wire, format, count)
  end

  def decode(wire, _format, _count),
    do: {:error, "pixels must be a binary, got: #{inspect(wire, limit: 5)}"}

  @doc "8-bit sRGB bytes (3 a pixel) of `pixels` in `format`."
  @spec to_srgb8(binary(), format()) :: binary()
  def to_srgb8(pixels, :srgb8), do: pixels

  def to_srgb8(pixels, :float) do
    {:ok, bytes} = Native.to_srgb8_binary(pixels)
    bytes
  end

  @doc """
  At most 4096 pixels in `format` as base64 text of their 8-bit sRGB bytes
  (the preview's encoding of an atom's pixels, piece by piece; on a normal
  scheduler).
  """
  @spec srgb8_base64(binary(), format()) :: binary()
  def srgb8_base64(piece, :float) do
    {:ok, text} = Native.to_srgb8_base64(piece)
    text
  end

  def srgb8_base64(piece, :srgb8) do
    {:ok, text} = Native.srgb8_base64(piece)
    text
  end
end
