defmodule RingTracer.Output.Pattern do
  @moduledoc false
  # Numbered output files: a run of `#` in a file name stands for the frame
  # number, zero-padded to the run's length, with more digits when the number
  # needs them (Blender's output pattern). `frames/orbit_####.png` names frame
  # 7 `frames/orbit_0007.png` and frame 12345 `frames/orbit_12345.png`.
  #
  # Only the file name is a pattern: a `#` in a folder of the path is taken as
  # it is, so every frame goes into the one folder. A name may hold one run of
  # `#` at most (`a_##_#.png` would be ambiguous).

  @enforce_keys [:dir, :prefix, :digits, :suffix]
  defstruct [:dir, :prefix, :digits, :suffix]

  @typedoc """
  A parsed pattern: the folder (`nil` when the path names none), the file
  name before and after the run of `#`, and the run's length (the fewest
  digits written).
  """
  @type t :: %__MODULE__{
          dir: Path.t() | nil,
          prefix: String.t(),
          digits: pos_integer(),
          suffix: String.t()
        }

  @doc """
  Parses `path`: `{:ok, pattern}` when its file name holds one run of `#`,
  `{:error, :none}` when it holds none, `{:error, :many}` when more than one.

      iex> {:ok, p} = RingTracer.Output.Pattern.parse("frames/orbit_####.png")
      iex> RingTracer.Output.Pattern.path(p, 7)
      "frames/orbit_0007.png"
      iex> RingTracer.Output.Pattern.path(p, 12345)
      "frames/orbit_12345.png"
      iex> RingTracer.Output.Pattern.parse("orbit.png")
      {:error, :none}
      iex> RingTracer.Output.Pattern.parse("a_##_#.png")
      {:error, :many}
      iex> {:ok, p} = RingTracer.Output.Pattern.parse("take#2/f_#.exr")
      iex> RingTracer.Output.Pattern.path(p, 3)
      "take#2/f_3.exr"
  """
  @spec parse(Path.t()) :: {:ok, t()} | {:error, :none | :many}
  def parse(path) when is_binary(path) do
    name = Path.basename(path)
    dir = if Path.basename(path) == path, do: nil, else: Path.dirname(path)

    case Regex.split(~r/#+/, name, include_captures: true) do
      [_] ->
        {:error, :none}

      [prefix, run, suffix] ->
        {:ok, %__MODULE__{dir: dir, prefix: prefix, digits: byte_size(run), suffix: suffix}}

      _ ->
        {:error, :many}
    end
  end

  @doc """
  Whether `path`'s file name holds a run of `#` (one or more).

      iex> RingTracer.Output.Pattern.pattern?("out/f_##.png")
      true
      iex> RingTracer.Output.Pattern.pattern?("out#1/f.png")
      false
  """
  @spec pattern?(Path.t()) :: boolean()
  def pattern?(path), do: String.contains?(Path.basename(path), "#")

  @doc """
  The path of frame `number` (frames are numbered from 1).

      iex> {:ok, p} = RingTracer.Output.Pattern.parse("/tmp/f_###.png")
      iex> Enum.map([1, 48, 1000], &RingTracer.Output.Pattern.path(p, &1))
      ["/tmp/f_001.png", "/tmp/f_048.png", "/tmp/f_1000.png"]
  """
  @spec path(t(), non_neg_integer()) :: Path.t()
  def path(%__MODULE__{} = p, number) when is_integer(number) and number >= 0 do
    name = p.prefix <> String.pad_leading(Integer.to_string(number), p.digits, "0") <> p.suffix

    if p.dir, do: Path.join(p.dir, name), else: name
  end

  @doc """
  The path of frame `number` for an `--out` path that may be a pattern:
  `path` itself when it holds no run of `#` (or, refused elsewhere, more
  than one).

      iex> RingTracer.Output.Pattern.expand("f_##.png", 4)
      "f_04.png"
      iex> RingTracer.Output.Pattern.expand("still.png", 4)
      "still.png"
  """
  @spec expand(Path.t(), non_neg_integer()) :: Path.t()
  def expand(path, number) do
    case parse(path) do
      {:ok, p} -> path(p, number)
      {:error, _} -> path
    end
  end
end
