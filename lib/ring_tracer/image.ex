defmodule RingTracer.Image do
  @moduledoc """
  Image files from linear RGB pixels (`RingTracer.Result`'s `:pixels`).

  The output file's extension picks the format: `.png` writes 8-bit sRGB
  (values clamped to [0, 1], then the sRGB transfer curve), `.exr` writes
  OpenEXR with linear 32-bit float RGB, lossless.

  Pixels already 8-bit sRGB (a job rendered with `pixels: :srgb8`, whose
  result's `:pixel_format` says so) are written as PNG only: the same file
  as of the floats they came from. An EXR of them is an error. Files are written
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
  def write(%Result{width: w, height: h, pixels: pixels, pixel_format: format}, path, opts \\ []),
    do: write(path, w, h, pixels, Keyword.put(opts, :format, format))

  @doc """
  Writes `width` x `height` `pixels` to `path`: options as `write/3`, and
  `:format`, the pixels' (`:float`, linear RGB floats, by default; or
  `:srgb8`, 3 bytes a pixel, `.png` only).
  """
  @spec write(Path.t(), pos_integer(), pos_integer(), binary(), keyword()) ::
          :ok | {:error, Error.t()}
  def write(path, width, height, pixels, opts \\ []) when is_binary(path) do
    ext = String.downcase(Path.extname(path))
    format = Keyword.get(opts, :format, :float)

    cond do
      ext not in @formats ->
        {:error,
         Error.new(:file, "#{path}: unknown image format #{inspect(ext)}; use .png or .exr")}

      format == :srgb8 and ext != ".png" ->
        {:error,
         Error.new(
           :file,
           "#{path}: 8-bit pixels (pixels: :srgb8) are written as .png only; " <>
             "render with pixels: :float for #{ext}"
         )}

      format not in RingTracer.Pixels.formats() ->
        {:error,
         Error.new(
           :invalid_option,
           "unknown pixel format #{inspect(format)}; use :float or :srgb8"
         )}

      true ->
        mode = opts[:mode] || -1
        written = write_native(format, opts[:in], path, {width, height, pixels, mode})

        case written do
          {:ok, _} -> :ok
          {:error, message} -> {:error, Error.new(:file, "#{path}: #{message}")}
        end
    end
  end

  defp write_native(:float, nil, path, {w, h, px, mode}),
    do: Native.write_image(Path.expand(path), w, h, px, mode)

  defp write_native(:float, dir, path, {w, h, px, mode}),
    do: Native.write_image_in(dir, Path.basename(path), w, h, px, mode)

  defp write_native(:srgb8, nil, path, {w, h, px, mode}),
    do: Native.write_png8(Path.expand(path), w, h, px, mode)

  defp write_native(:srgb8, dir, path, {w, h, px, mode}),
    do: Native.write_png8_in(dir, Path.basename(path), w, h, px, mode)

  @doc "8-bit sRGB bytes (3 a pixel) of `pixels` in `format` (linear RGB floats by default)."
  @spec srgb8(binary(), :float | :srgb8) :: binary()
  def srgb8(pixels, format \\ :float), do: RingTracer.Pixels.to_srgb8(pixels, format)

  @doc """
  The result's image as PNG bytes (8-bit sRGB), e.g. to show in Livebook
  (`Kino.Image.new(bytes, :png)`) or to send over HTTP.

      iex> {:ok, result} = RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 8, children: 1, atoms: 1)
      iex> {:ok, <<0x89, "PNG", _::binary>>} = RingTracer.Image.to_png(result)
      iex> :ok
      :ok
  """
  @spec to_png(Result.t()) :: {:ok, binary()} | {:error, Error.t()}
  def to_png(%Result{width: w, height: h, pixels: pixels, pixel_format: format}),
    do: png(w, h, pixels, format)

  @doc "Like `to_png/1`, but returns the bytes or raises `RingTracer.Error`."
  @spec to_png!(Result.t()) :: binary()
  def to_png!(result) do
    case to_png(result) do
      {:ok, bytes} -> bytes
      {:error, error} -> raise error
    end
  end

  @doc """
  A PNG file's bytes for `width` x `height` `pixels` in `format`: linear
  RGB floats (`:float`, default) or 8-bit sRGB (`:srgb8`), the same bytes
  for the same image.
  """
  @spec png(pos_integer(), pos_integer(), binary(), :float | :srgb8) ::
          {:ok, binary()} | {:error, Error.t()}
  def png(width, height, pixels, format \\ :float) do
    encoded =
      case format do
        :float -> Native.encode_png(width, height, pixels)
        :srgb8 -> Native.encode_png8(width, height, pixels)
      end

    case encoded do
      {:ok, bytes} -> {:ok, bytes}
      {:error, message} -> {:error, Error.new(:file, message)}
    end
  end
end
