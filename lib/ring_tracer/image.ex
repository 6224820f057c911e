defmodule RingTracer.Image do
  @moduledoc """
  Image files from linear RGB pixels (`RingTracer.Result`'s `:pixels`).

  The output file's extension picks the format: `.png` writes 8-bit sRGB
  (values clamped to [0, 1], then the sRGB transfer curve), `.exr` writes
  OpenEXR with linear 32-bit float RGB, lossless. Files are written
  atomically: to a temporary file in the same folder, then renamed, so an
  earlier file is never left half-written.
  """

  alias RingTracer.{Error, Native, Result}

  @formats [".png", ".exr"]

  @doc """
  Writes the result's image to `path`.

  Returns `{:error, %RingTracer.Error{reason: :file}}` for an unknown
  extension or a file that cannot be written.
  """
  @spec write(Result.t(), Path.t()) :: :ok | {:error, Error.t()}
  def write(%Result{width: w, height: h, pixels: pixels}, path), do: write(path, w, h, pixels)

  @doc "Writes `width` x `height` linear RGB float `pixels` to `path`."
  @spec write(Path.t(), pos_integer(), pos_integer(), binary()) :: :ok | {:error, Error.t()}
  def write(path, width, height, pixels) when is_binary(path) do
    ext = String.downcase(Path.extname(path))

    cond do
      ext not in @formats ->
        {:error,
         Error.new(:file, "#{path}: unknown image format #{inspect(ext)}; use .png or .exr")}

      true ->
        case Native.write_image(Path.expand(path), width, height, pixels) do
          {:ok, _} -> :ok
          {:error, message} -> {:error, Error.new(:file, "#{path}: #{message}")}
        end
    end
  end

  @doc "8-bit sRGB bytes (3 a pixel) of linear RGB float `pixels`."
  @spec srgb8(binary()) :: binary()
  def srgb8(pixels) do
    {:ok, bytes} = Native.to_srgb8_binary(pixels)
    bytes
  end

  @doc "A PNG file's bytes for `width` x `height` linear RGB float `pixels`."
  @spec png(pos_integer(), pos_integer(), binary()) :: {:ok, binary()} | {:error, Error.t()}
  def png(width, height, pixels) do
    case Native.encode_png(width, height, pixels) do
      {:ok, bytes} -> {:ok, bytes}
      {:error, message} -> {:error, Error.new(:file, message)}
    end
  end
end
