defmodule RingTracer.Settings do
  @moduledoc """
  What the kernel needs to trace a pixel: image size, ray-tree depth,
  adaptive cut-off, samples per pixel, SPD corner mode. The same settings and
  scene give the same bytes for every pixel wherever it is traced.
  """

  @enforce_keys [:width, :height]
  defstruct width: nil, height: nil, depth: 5, cutoff: 1 / 255, samples: 1, spd: false

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          depth: pos_integer(),
          cutoff: float(),
          samples: pos_integer(),
          spd: boolean()
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
      spd: s.spd
    }
  end
end
