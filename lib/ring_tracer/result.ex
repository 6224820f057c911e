defmodule RingTracer.Result do
  @moduledoc """
  A finished render: the image as linear RGB and what the job did.

    * `:pixels` — `width * height * 3` native-endian 32-bit floats, row-major
      from the top-left, linear light (write it with `RingTracer.Image`);
    * `:elapsed_us` — the job's wall time, from starting the parent to the
      last atom, in microseconds;
    * `:children` — one map per child, in ring order: `:index`, `:node`,
      atoms `:own`, `:given`, `:received`, `:handovers` (hand-over messages received), `:traced`, help offers
      `:offers_sent`, `:offers_passed`, `:offers_consumed`,
      `:grandchild_restarts`, `:busy_us` (time its grandchild spent tracing)
      and `:rays`;
    * `:rays` — ray counters summed over all atoms: `:eye`, `:eye_hits`,
      `:reflected`, `:refracted`, `:shadow`.
  """

  @enforce_keys [:width, :height, :pixels, :elapsed_us, :children, :rays, :settings]
  defstruct [:width, :height, :pixels, :elapsed_us, :children, :rays, :settings]

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          pixels: binary(),
          elapsed_us: non_neg_integer(),
          children: [map()],
          rays: map(),
          settings: RingTracer.Settings.t()
        }

  @doc false
  @spec new(RingTracer.Settings.t(), map()) :: t()
  def new(settings, %{pixels: pixels, elapsed_us: us, children: children}) do
    rays =
      Enum.reduce(children, %{eye: 0, eye_hits: 0, reflected: 0, refracted: 0, shadow: 0}, fn c,
                                                                                              acc ->
        Map.merge(acc, c.rays, fn _, a, b -> a + b end)
      end)

    %__MODULE__{
      width: settings.width,
      height: settings.height,
      pixels: pixels,
      elapsed_us: us,
      children: children,
      rays: rays,
      settings: settings
    }
  end
end
