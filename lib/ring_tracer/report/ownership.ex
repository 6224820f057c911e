defmodule RingTracer.Report.Ownership do
  @moduledoc false
  # The rendered image tinted by who computed it: every pixel of an atom is
  # mixed 50/50 (in linear light) with the colour of the child that traced that
  # atom (`RingTracer.Report.Palette`, the colours of
  # `RingTracer.Report.Timeline`). With no load balancing the tints follow the
  # children's strips; atoms handed to a helper show up in the helper's colour.
  #
  # A job rendered with `pixels: :srgb8` has no linear values left to mix:
  # rendered with `ownership: true`, its children tint each atom as they send
  # it (the same mix, in the same arithmetic) and the result holds the map
  # in `:tinted`, which `write/3` writes, byte for byte the map of the floats.

  alias RingTracer.{Error, Image, Layout, Pixels, Result}
  alias RingTracer.Report.Palette

  @doc """
  The tinted image of a result in linear floats (`pixel_format: :float`):
  `width * height * 3` native-endian 32-bit floats, linear RGB, like
  `RingTracer.Result`'s `:pixels`. Pixels of atoms missing from
  `result.atoms` are left as they are.
  """
  @spec pixels(Result.t()) :: binary()
  def pixels(
        %Result{children: children, atoms: atoms, pixels: pixels, pixel_format: :float} = result
      )
      when is_list(atoms) and atoms != [] and is_list(children) and children != [] do
    n = length(children)
    k = max(div(atoms |> Enum.uniq_by(&Layout.base(&1.atom)) |> length(), n), 1)
    layout = Layout.new(result.width, result.height, n, k)
    tracer = Map.new(atoms, &{&1.atom, &1.child})
    colours = children |> Enum.with_index() |> Map.new(fn {_, i} -> {i, Palette.linear(i)} end)
    # Atoms traced in pieces: each piece tinted for its tracer.
    pieces = atoms |> Enum.map(& &1.atom) |> Enum.group_by(&Layout.base/1)

    layout
    |> Layout.atoms()
    |> Enum.flat_map(&Map.get(pieces, &1, [&1]))
    |> Enum.sort_by(&Layout.span(layout, &1))
    |> Enum.map(fn a ->
      {first, count} = Layout.span(layout, a)
      chunk = Pixels.slice(pixels, :float, first, count)

      case Map.fetch(tracer, a) do
        {:ok, child} -> tint(chunk, Map.get_lazy(colours, child, fn -> Palette.linear(child) end))
        :error -> chunk
      end
    end)
    |> IO.iodata_to_binary()
  end

  def pixels(%Result{pixels: pixels}), do: pixels

  @doc """
  Writes the tinted image of `result` to `path` with `RingTracer.Image.write/5`
  (`.png`; `.exr` works too for a result in floats), whose options it takes.
  A result in `:srgb8` needs its `:tinted` image (rendered with
  `ownership: true`).
  """
  @spec write(Result.t(), Path.t(), keyword()) :: :ok | {:error, Error.t()}
  def write(result, path, opts \\ [])

  def write(%Result{tinted: tinted} = result, path, opts)
      when is_binary(tinted) and is_binary(path),
      do:
        Image.write(path, result.width, result.height, tinted, Keyword.put(opts, :format, :srgb8))

  def write(%Result{pixel_format: :srgb8}, path, _opts) when is_binary(path),
    do:
      {:error,
       Error.new(
         :invalid_option,
         "#{path}: the ownership map of a job rendered with pixels: :srgb8 needs " <>
           "ownership: true (the children tint the atoms as they send them)"
       )}

  def write(%Result{} = result, path, opts) when is_binary(path),
    do: Image.write(path, result.width, result.height, pixels(result), opts)

  defp tint(chunk, {cr, cg, cb}) do
    for <<r::float-32-native, g::float-32-native, b::float-32-native <- chunk>>, into: <<>> do
      <<(r + cr) / 2::float-32-native, (g + cg) / 2::float-32-native,
        (b + cb) / 2::float-32-native>>
    end
  end
end
