defmodule RingTracer.Sequence do
  @moduledoc false
  # The options only a sequence has (`RingTracer.render_sequence/2`):
  # which of the scene's frames, how many in flight at once, and whether
  # a frame leaves the window only once the caller acknowledges it.

  alias RingTracer.Error

  @default_window 4
  @max_window 64

  @doc "The most frames a sequence may have in flight."
  @spec max_window() :: pos_integer()
  def max_window, do: @max_window

  @doc "The default number of frames in flight."
  @spec default_window() :: pos_integer()
  def default_window, do: @default_window

  @doc """
  `:frames` (a range or an ascending list of the scene's frame numbers,
  from 1; default all), `:window` and `:ack` checked against a scene of
  `count` frames named `name`: the frames from 0, the window and ack.

      iex> RingTracer.Sequence.options([frames: 3..5], 24, "fly.toml")
      {:ok, [2, 3, 4], 4, false}
      iex> RingTracer.Sequence.options([frames: [1, 24], window: 2, ack: true], 24, "fly.toml")
      {:ok, [0, 23], 2, true}
      iex> {:error, e} = RingTracer.Sequence.options([frames: 20..30], 24, "fly.toml")
      iex> e.message
      "option :frames must name frames from 1 to 24 (the frames of fly.toml), got: 20..30"
  """
  @spec options(keyword(), pos_integer(), String.t()) ::
          {:ok, [non_neg_integer(), ...], pos_integer(), boolean()} | {:error, Error.t()}
  def options(opts, count, name) do
    frames = Keyword.get(opts, :frames, 1..count)
    window = Keyword.get(opts, :window, @default_window)
    ack = Keyword.get(opts, :ack, false)

    cond do
      not frames?(frames) ->
        invalid(
          ":frames must be a range of frame numbers with step 1 or a non-empty, " <>
            "strictly ascending list of them",
          frames
        )

      Enum.min(frames) < 1 or Enum.max(frames) > count ->
        invalid(
          ":frames must name frames from 1 to #{count} (the frames of #{name})",
          frames
        )

      not (is_integer(window) and window in 1..@max_window) ->
        invalid(":window must be an integer from 1 to #{@max_window}", window)

      not is_boolean(ack) ->
        invalid(":ack must be a boolean", ack)

      true ->
        {:ok, Enum.map(frames, &(&1 - 1)), window, ack}
    end
  end

  defp frames?(%Range{first: a, last: b, step: 1}) when is_integer(a) and a <= b, do: true

  defp frames?([_ | _] = list) do
    Enum.all?(list, &is_integer/1) and
      list |> Enum.chunk_every(2, 1, :discard) |> Enum.all?(fn [a, b] -> a < b end)
  end

  defp frames?(_other), do: false

  defp invalid(what, value),
    do: {:error, Error.new(:invalid_option, "option #{what}, got: #{inspect(value)}")}
end
