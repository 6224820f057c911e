defmodule RingTracer.Settings do
  @moduledoc false
  # What the kernel needs to trace a pixel: image size, ray-tree depth,
  # adaptive cut-off, samples per pixel, SPD corner mode, and the region of
  # the image traced (the camera still frames the whole image, so a region
  # holds exactly the whole render's pixels there). The same settings and
  # scene give the same bytes for every pixel wherever it is traced.

  # The kernel's defaults (`Settings::new` in native/kernel/src/render.rs),
  # read through the NIF when this module compiles: they are written down
  # nowhere else.
  @external_resource "native/kernel/src/render.rs"
  @external_resource "native/kernel/src/limits.rs"
  @defaults RingTracer.Native.settings_defaults()
  @limits RingTracer.Native.settings_limits()

  @enforce_keys [:width, :height]
  defstruct width: nil,
            height: nil,
            depth: @defaults.depth,
            cutoff: @defaults.cutoff,
            samples: @defaults.samples,
            spd: @defaults.spd,
            region: nil

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          depth: pos_integer(),
          cutoff: float(),
          samples: pos_integer(),
          spd: boolean(),
          region: region() | nil
        }

  @typedoc "Part of the image, in pixels: `{x0, y0, width, height}` (y = 0 is the top row)."
  @type region :: {non_neg_integer(), non_neg_integer(), pos_integer(), pos_integer()}

  @doc """
  The defaults of the settings a render may leave out, the kernel's own.

      iex> d = RingTracer.Settings.defaults()
      iex> {d.depth, round(1 / d.cutoff), d.samples, d.spd}
      {5, 255, 1, false}
  """
  @spec defaults() :: %{
          depth: pos_integer(),
          cutoff: float(),
          samples: pos_integer(),
          spd: boolean()
        }
  def defaults, do: @defaults

  @doc """
  The kernel's limits on a render's settings (`native/kernel/src/limits.rs`),
  read through the NIF: the largest image side and area, samples, depth and
  frames of an animation.

      iex> l = RingTracer.Settings.limits()
      iex> {l.max_side, l.max_samples, l.max_depth}
      {16384, 16, 64}
  """
  @spec limits() :: %{
          max_side: pos_integer(),
          max_pixels: pos_integer(),
          max_samples: pos_integer(),
          max_depth: pos_integer(),
          max_frames: pos_integer()
        }
  def limits, do: @limits

  @doc """
  A default as the docs and `--help` show it: the cut-off as a fraction.

      iex> RingTracer.Settings.shown_default(:cutoff)
      "1/255"
      iex> RingTracer.Settings.shown_default(:depth)
      "5"
  """
  @spec shown_default(:depth | :cutoff | :samples | :spd) :: String.t()
  def shown_default(:cutoff), do: "1/#{round(1 / @defaults.cutoff)}"
  def shown_default(key), do: to_string(Map.fetch!(@defaults, key))

  @doc """
  The size of what is traced: the region's, or the whole image's.

      iex> RingTracer.Settings.traced_size(%RingTracer.Settings{width: 64, height: 48, region: {8, 4, 16, 10}})
      {16, 10}
      iex> RingTracer.Settings.traced_size(%RingTracer.Settings{width: 64, height: 48})
      {64, 48}
  """
  @spec traced_size(t()) :: {pos_integer(), pos_integer()}
  def traced_size(%__MODULE__{region: {_, _, w, h}}), do: {w, h}
  def traced_size(%__MODULE__{width: w, height: h}), do: {w, h}

  @doc "The map the NIF decodes."
  @spec to_native(t()) :: map()
  def to_native(%__MODULE__{} = s) do
    %{
      width: s.width,
      height: s.height,
      depth: s.depth,
      cutoff: s.cutoff / 1,
      samples: s.samples,
      spd: s.spd,
      region: s.region
    }
  end
end
