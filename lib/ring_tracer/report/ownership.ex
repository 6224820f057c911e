defmodule RingTracer.Report.Ownership do
  @moduledoc """
  The rendered image tinted by who computed it: every pixel of an atom is
  mixed 50/50 (in linear light) with the colour of the child that traced that
  atom (`RingTracer.Report.Palette`, the colours of
  `RingTracer.Report.Timeline`). With no load balancing the tints follow the
  children's strips; atoms handed to a helper show up in the helper's colour.
  """

  alias RingTracer.{Error, Image, Layout, Result}
  alias RingTracer.Report.Palette

  @doc """
  The tinted image: `width * height * 3` native-endian 32-bit floats, linear
  RGB, like `RingTracer.Result`'s `:pixels`. Pixels of atoms missing from
  `result.atoms` are left as they are.
  """
  @spec pixels(Result.t()) :: binary()
  def pixels(%Result{children: children, atoms: atoms, pixels: pixels} = result)
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
      chunk = binary_part(pixels, first * 12, count * 12)

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
  (`.png`; `.exr` works too), whose options it takes.
  """
  @spec write(Result.t(), Path.t(), keyword()) :: :ok | {:error, Error.t()}
  def write(%Result{} = result, path, opts \\ []) when is_binary(path) do
    Image.write(path, result.width, result.height, pixels(result), opts)
  end

  defp tint(chunk, {cr, cg, cb}) do
    for <<r::float-32-native, g::float-32-native, b::float-32-native <- chunk>>, into: <<>> do
      <<(r + cr) / 2::float-32-native, (g + cg) / 2::float-32-native,
        (b + cb) / 2::float-32-native>>
    end
  end
end
