defmodule RingTracer.Test.PNG do
  @moduledoc "Decodes 8-bit RGB and RGBA PNG files (what the kernel and a browser canvas write), for comparing pixels."

  @doc "`{width, height, channels, pixels}`: rows top to bottom, unfiltered."
  @spec decode(binary()) :: {pos_integer(), pos_integer(), 3 | 4, binary()}
  def decode(<<0x89, "PNG\r\n", 0x1A, "\n", rest::binary>>) do
    {ihdr, data} = chunks(rest, nil, [])
    <<w::32, h::32, 8, type, 0, 0, 0>> = ihdr
    channels = %{2 => 3, 6 => 4}[type] || raise "PNG colour type #{type} not handled"
    raw = :zlib.uncompress(IO.iodata_to_binary(data))
    {w, h, channels, unfilter(raw, w * channels, channels, :binary.copy(<<0>>, w * channels), [])}
  end

  defp chunks(
         <<len::32, type::binary-4, body::binary-size(len), _crc::32, rest::binary>>,
         ihdr,
         data
       ) do
    case type do
      "IHDR" -> chunks(rest, body, data)
      "IDAT" -> chunks(rest, ihdr, [data, body])
      "IEND" -> {ihdr, data}
      _ -> chunks(rest, ihdr, data)
    end
  end

  defp unfilter(<<>>, _stride, _bpp, _prev, acc),
    do: acc |> Enum.reverse() |> IO.iodata_to_binary()

  defp unfilter(<<filter, data::binary>>, stride, bpp, prev, acc) do
    <<line::binary-size(stride), rest::binary>> = data
    row = row(filter, line, prev, bpp)
    unfilter(rest, stride, bpp, row, [row | acc])
  end

  defp row(0, line, _prev, _bpp), do: line

  defp row(filter, line, prev, bpp) do
    line = :binary.bin_to_list(line)
    up = :binary.bin_to_list(prev)
    up_t = List.to_tuple(up)

    {out, _} =
      line
      |> Enum.zip(up)
      |> Enum.with_index()
      |> Enum.reduce({[], []}, fn {{x, b}, i}, {out, _} ->
        a = if i >= bpp, do: Enum.at(out, bpp - 1), else: 0
        c = if i >= bpp, do: elem(up_t, i - bpp), else: 0

        v =
          case filter do
            1 -> x + a
            2 -> x + b
            3 -> x + div(a + b, 2)
            4 -> x + paeth(a, b, c)
          end

        {[rem(v, 256) | out], nil}
      end)

    out |> Enum.reverse() |> :binary.list_to_bin()
  end

  defp paeth(a, b, c) do
    p = a + b - c
    {pa, pb, pc} = {abs(p - a), abs(p - b), abs(p - c)}

    cond do
      pa <= pb and pa <= pc -> a
      pb <= pc -> b
      true -> c
    end
  end
end
