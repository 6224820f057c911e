defmodule RingTracer.Settings do
  @moduledoc """
  What the kernel needs to trace a pixel: image size, ray-tree depth,
  adaptive cut-off, samples per pixel, SPD corner mode. The same settings and
  scene give the same bytes for every pixel wherever it is traced.

  `:fail_pixel` is a test hook: the kernel panics when it traces that pixel
  (to show that a panic is contained). It is `nil` in normal use.
  """

  @enforce_keys [:width, :height]
  defstruct width: nil,
            height: nil,
            depth: 5,
            cutoff: 1 / 255,
            samples: 1,
            spd: false,
            fail_pixel: nil

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          depth: pos_integer(),
          cutoff: float(),
          samples: pos_integer(),
          spd: boolean(),
          fail_pixel: non_neg_integer() | nil
        }

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
      fail_pixel: s.fail_pixel
    }
  end
end
