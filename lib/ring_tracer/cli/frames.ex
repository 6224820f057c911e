defmodule RingTracer.CLI.Frames do
  @moduledoc false
  # Which frames of a scene `ringtracer render` renders, and the file each
  # goes to, from `--frame`, `--frames` and `--out`
  # (`RingTracer.Output.Pattern`).
  #
  #   * `--frame F`: frame F alone.
  #   * `--frames A-B` (or `--frames N`): frames A to B, inclusive, from 1;
  #     more than one is a sequence, whose `--out` must hold a run of `#`.
  #   * Neither: every frame of an animated scene when `--out` holds a run of
  #     `#`, else frame 1 (a still's only frame).
  #
  # A run of `#` in `--out` is always the frame number, for one frame too.

  alias RingTracer.Output.Pattern

  @enforce_keys [:numbers, :out, :pattern, :sequence?]
  defstruct [:numbers, :out, :pattern, :sequence?]

  @typedoc """
  The frames to render (from 1, ascending), `--out` as given, its pattern
  (`nil`: none) and whether the frames are rendered as one sequence job
  (more than one frame asked for) rather than as one frame.
  """
  @type t :: %__MODULE__{
          numbers: [pos_integer(), ...],
          out: Path.t(),
          pattern: Pattern.t() | nil,
          sequence?: boolean()
        }

  @doc """
  Checks `--out` alone, before the scene is read: a run of `#` at most in
  its file name.

      iex> RingTracer.CLI.Frames.check_out("f_#_#.png")
      {:usage, "--out f_#_#.png: one run of # in the file name stands for the frame number; this one has more"}
      iex> RingTracer.CLI.Frames.check_out("f_#.png")
      :ok
  """
  @spec check_out(Path.t()) :: :ok | {:usage, String.t()}
  def check_out(out) do
    case Pattern.parse(out) do
      {:error, :many} ->
        {:usage,
         "--out #{out}: one run of # in the file name stands for the frame number; this one has more"}

      _ ->
        :ok
    end
  end

  @doc """
  Parses the text of `--frames`: `A-B` (inclusive, `1 <= A <= B`) or `N`.

      iex> RingTracer.CLI.Frames.parse("3-10")
      {:ok, 3..10}
      iex> RingTracer.CLI.Frames.parse("7")
      {:ok, 7..7}
      iex> RingTracer.CLI.Frames.parse("10-3")
      {:usage, "--frames takes A-B (frames A to B, from 1, A <= B) or N (frame N), got: 10-3"}
  """
  @spec parse(String.t()) :: {:ok, Range.t()} | {:usage, String.t()}
  def parse(text) do
    parts = text |> String.split("-") |> Enum.map(&Integer.parse(String.trim(&1)))

    case parts do
      [{n, ""}] when n >= 1 ->
        {:ok, n..n}

      [{a, ""}, {b, ""}] when a >= 1 and a <= b ->
        {:ok, a..b}

      _ ->
        {:usage,
         "--frames takes A-B (frames A to B, from 1, A <= B) or N (frame N), got: #{text}"}
    end
  end

  @doc """
  The plan for the command line's `opts` (`:frame`, `:frames`), its
  `--out` path `out`, and a scene of `count` frames named `scene` (for
  errors). Usage errors name the option, and the scene and its count when
  the frames asked for are not all in it.

      iex> RingTracer.CLI.Frames.plan([frames: "40-60"], "f_#.png", 48, "orbit.toml")
      {:usage, "--frames 40-60: orbit.toml has 48 frames (1 to 48)"}
      iex> RingTracer.CLI.Frames.plan([frame: 2, frames: "1-3"], "f_#.png", 48, "orbit.toml")
      {:usage, "give --frame F (one frame) or --frames A-B (a sequence), not both"}

      iex> {:ok, plan} = RingTracer.CLI.Frames.plan([], "f_##.png", 3, "orbit.toml")
      iex> {plan.numbers, plan.sequence?, RingTracer.CLI.Frames.path(plan, 3)}
      {[1, 2, 3], true, "f_03.png"}
      iex> {:ok, plan} = RingTracer.CLI.Frames.plan([], "f.png", 3, "orbit.toml")
      iex> {plan.numbers, plan.sequence?, RingTracer.CLI.Frames.path(plan, 1)}
      {[1], false, "f.png"}
      iex> RingTracer.CLI.Frames.plan([frames: "2-3"], "f.png", 3, "orbit.toml")
      {:usage, "--out f.png: a sequence of 2 frames needs a run of # in the file name for the frame number, e.g. f_####.png"}
  """
  @spec plan(keyword(), Path.t(), pos_integer(), String.t()) :: {:ok, t()} | {:usage, String.t()}
  def plan(opts, out, count, scene) do
    pattern =
      case Pattern.parse(out) do
        {:ok, p} -> p
        {:error, _} -> nil
      end

    with :ok <- check_out(out),
         {:ok, numbers} <- numbers(opts, pattern, count, scene) do
      sequence? = length(numbers) > 1

      if sequence? and pattern == nil,
        do:
          {:usage,
           "--out #{out}: a sequence of #{length(numbers)} frames needs a run of # in the " <>
             "file name for the frame number, e.g. #{example(out)}"},
        else:
          {:ok, %__MODULE__{numbers: numbers, out: out, pattern: pattern, sequence?: sequence?}}
    end
  end

  defp numbers(opts, pattern, count, scene) do
    case {opts[:frame], opts[:frames]} do
      {f, t} when f != nil and t != nil ->
        {:usage, "give --frame F (one frame) or --frames A-B (a sequence), not both"}

      {nil, nil} ->
        {:ok, if(pattern != nil, do: Enum.to_list(1..count), else: [1])}

      {f, nil} when f <= count ->
        {:ok, [f]}

      {f, nil} ->
        {:usage, "--frame must be at most #{count} (the frames of #{scene}), got: #{f}"}

      {nil, text} ->
        with {:ok, a..b//1} <- parse(text) do
          if b <= count,
            do: {:ok, Enum.to_list(a..b)},
            else: {:usage, "--frames #{text}: #{scene} has #{frames(count)}"}
        end
    end
  end

  defp frames(1), do: "1 frame (a still)"
  defp frames(n), do: "#{n} frames (1 to #{n})"

  defp example(out) do
    ext = Path.extname(out)
    Path.basename(out, ext) <> "_####" <> ext
  end

  @doc "The file frame `number` of `plan` goes to."
  @spec path(t(), pos_integer()) :: Path.t()
  def path(%__MODULE__{pattern: nil, out: out}, _number), do: out
  def path(%__MODULE__{pattern: pattern}, number), do: Pattern.path(pattern, number)

  @doc """
  The frames of `plan` whose file is already complete in its folder `dir`
  (`RingTracer.Output.open_dir/1`, `RingTracer.Output.complete?/2`), for
  `--continue`, and those left to render.
  """
  @spec done(t(), RingTracer.Output.dir()) :: {[pos_integer()], [pos_integer()]}
  def done(plan, dir) do
    Enum.split_with(plan.numbers, fn n ->
      RingTracer.Output.complete?(dir, Path.basename(path(plan, n)))
    end)
  end
end
