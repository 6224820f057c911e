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

  ## Options

    * `:mode` — the permissions of a new file (default: `0o666` less the
      umask); a file replaced keeps its own
    * `:in` — the folder of `path` already held open (see
      `RingTracer.Output.write_all/1`): written there under `path`'s name
  """
  @spec write(Result.t(), Path.t(), keyword()) :: :ok | {:error, Error.t()}
  def write(%Result{width: w, height: h, pixels: pixels}, path, opts \\ []),
    do: write(path, w, h, pixels, opts)

  @doc "Writes `width` x `height` linear RGB float `pixels` to `path` (options as `write/3`)."
  @spec write(Path.t(), pos_integer(), pos_integer(), binary(), keyword()) ::
          :ok | {:error, Error.t()}
  def write(path, width, height, pixels, opts \\ []) when is_binary(path) do
    ext = String.downcase(Path.extname(path))

    cond do
      ext not in @formats ->
        {:error,
         Error.new(:file, "#{path}: unknown image format #{inspect(ext)}; use .png or .exr")}

      true ->
        mode = opts[:mode] || -1

        written =
          case opts[:in] do
            nil -> Native.write_image(Path.expand(path), width, height, pixels, mode)
            dir -> Native.write_image_in(dir, Path.basename(path), width, height, pixels, mode)
          end

        case written do
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

  @doc """
  The result's image as PNG bytes (8-bit sRGB), e.g. to show in Livebook
  (`Kino.Image.new(bytes, :png)`) or to send over HTTP.

      iex> {:ok, result} = RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 8, children: 1, atoms: 1)
      iex> {:ok, <<0x89, "PNG", _::binary>>} = RingTracer.Image.to_png(result)
      iex> :ok
      :ok
  """
  @spec to_png(Result.t()) :: {:ok, binary()} | {:error, Error.t()}
  def to_png(%Result{width: w, height: h, pixels: pixels}), do: png(w, h, pixels)

  @doc "Like `to_png/1`, but returns the bytes or raises `RingTracer.Error`."
  @spec to_png!(Result.t()) :: binary()
  def to_png!(result) do
    case to_png(result) do
      {:ok, bytes} -> bytes
      {:error, error} -> raise error
    end
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
