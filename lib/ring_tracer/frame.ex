defmodule RingTracer.Frame do
  @moduledoc """
  One frame of a sequence (`RingTracer.render_sequence/2`), as it completes:
  its number in the scene (from 1), its image (`pixels`: linear RGB,
  native-endian f32 triples, row-major, like `RingTracer.Result`'s), and
  `pixel_format`, the format of `pixels` (`:float`, or `:srgb8` for a job
  rendered with `pixels: :srgb8`: 8-bit sRGB, 3 bytes a pixel; see
  `RingTracer.render/2`), and
  when it was traced: `released_us`, when the job put its atoms in the
  ring, and `completed_us`, when its last pixel arrived (job microseconds,
  from the job's start). `atoms` counts its atoms, `traced` how many atoms
  or pieces each child traced of it, `rays` its ray counters
  (`RingTracer.Rays`).
  """

  @enforce_keys [:number, :width, :height, :pixels]
  defstruct [
    :number,
    :width,
    :height,
    :pixels,
    pixel_format: :float,
    released_us: 0,
    completed_us: 0,
    atoms: 0,
    traced: %{},
    rays: %{}
  ]

  @type t :: %__MODULE__{
          number: pos_integer(),
          width: pos_integer(),
          height: pos_integer(),
          pixels: binary() | nil,
          pixel_format: :float | :srgb8,
          released_us: integer(),
          completed_us: integer(),
          atoms: non_neg_integer(),
          traced: %{non_neg_integer() => non_neg_integer()},
          rays: map()
        }

  @doc """
  The frame without its pixels: what a sequence's result keeps of each
  frame (`RingTracer.Result`'s `:frames`).
  """
  @spec summary(t()) :: t()
  def summary(%__MODULE__{} = frame), do: %{frame | pixels: nil}

  @doc "Microseconds from the frame's release to its last pixel."
  @spec elapsed_us(t()) :: non_neg_integer()
  def elapsed_us(%__MODULE__{released_us: r, completed_us: c}), do: max(c - r, 0)
end

defimpl Inspect, for: RingTracer.Frame do
  def inspect(f, _opts) do
    ms = :erlang.float_to_binary(RingTracer.Frame.elapsed_us(f) / 1000, decimals: 1)
    "#RingTracer.Frame<#{f.number}, #{f.width}x#{f.height}, #{ms} ms, #{f.atoms} atoms>"
  end
end
