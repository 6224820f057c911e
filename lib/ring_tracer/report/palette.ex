defmodule RingTracer.Report.Palette do
  @moduledoc false
  # One colour per child, shared by the reports (`RingTracer.Report.Timeline`
  # bars and `RingTracer.Report.Ownership` tints).
  #
  # Child `i` gets hue `i * 137.508°` (the golden angle) at fixed saturation
  # and lightness, so neighbouring children — and any number of them — get
  # well separated hues.

  @golden_angle 137.50776405003785
  @saturation 0.66
  @lightness 0.55

  @doc "Child `i`'s colour as sRGB components in `0.0..1.0`."
  @spec srgb(non_neg_integer()) :: {float(), float(), float()}
  def srgb(i) when is_integer(i) and i >= 0 do
    hue = :math.fmod(i * @golden_angle, 360.0)
    hsl_to_rgb(hue, @saturation, @lightness)
  end

  @doc """
  Child `i`'s colour as a CSS hex string, `\"#rrggbb\"`.

      iex> RingTracer.Report.Palette.hex(0)
      "#d84141"
      iex> RingTracer.Report.Palette.hex(0) == RingTracer.Report.Palette.hex(1)
      false
  """
  @spec hex(non_neg_integer()) :: String.t()
  def hex(i) do
    {r, g, b} = srgb(i)
    "#" <> Enum.map_join([r, g, b], &byte_hex/1)
  end

  @doc """
  Child `i`'s colour in linear light (the space of `RingTracer.Result`'s
  pixels), components in `0.0..1.0`.
  """
  @spec linear(non_neg_integer()) :: {float(), float(), float()}
  def linear(i) do
    {r, g, b} = srgb(i)
    {to_linear(r), to_linear(g), to_linear(b)}
  end

  defp byte_hex(c) do
    c
    |> Kernel.*(255)
    |> round()
    |> Integer.to_string(16)
    |> String.pad_leading(2, "0")
    |> String.downcase()
  end

  defp to_linear(c) when c <= 0.04045, do: c / 12.92
  defp to_linear(c), do: :math.pow((c + 0.055) / 1.055, 2.4)

  defp hsl_to_rgb(h, s, l) do
    c = (1 - abs(2 * l - 1)) * s
    hp = h / 60
    x = c * (1 - abs(:math.fmod(hp, 2) - 1))

    {r, g, b} =
      cond do
        hp < 1 -> {c, x, 0.0}
        hp < 2 -> {x, c, 0.0}
        hp < 3 -> {0.0, c, x}
        hp < 4 -> {0.0, x, c}
        hp < 5 -> {x, 0.0, c}
        true -> {c, 0.0, x}
      end

    m = l - c / 2
    {r + m, g + m, b + m}
  end
end
