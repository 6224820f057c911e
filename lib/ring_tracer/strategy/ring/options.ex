defmodule RingTracer.Strategy.Ring.Options do
  @moduledoc false
  # The ring's options (`RingTracer.Strategy.Ring.options/2`): each checked,
  # and each default written here once.
  #
  #   * `:hold_after` — hops an offer walks before it may wait at a child
  #     about to run out (`RingTracer.Strategy.Ring.HelpOffer`);
  #   * `:aim` — whether an idle child sends its offer straight to the
  #     sibling it expects to stay busy longest (`RingTracer.Strategy.Ring.Aim`);
  #     by default, on contiguous strips of one image; it works within one
  #     image, so a sequence of several frames refuses `aim: true`;
  #   * `:split` — adaptive atoms (`RingTracer.Strategy.Ring.Share.part/7`,
  #     `RingTracer.Job.Pipe.cut/3`); `false`, the default, keeps atoms
  #     whole, as the paper does;
  #   * `:part_us`, `:part_rows` — with `:split`, the shortest part worth a
  #     kernel call of its own, in microseconds of the child's wall time per
  #     atom and in image rows; `:cut_faster` — how much faster than a child
  #     an offerer must be to take parts of its atom being traced.

  alias RingTracer.Layout
  alias RingTracer.Strategy.Ring.HelpOffer

  @doc """
  The ring's options as given, checked, with every default filled in, for a
  job of layout `layout`.

      iex> layout = RingTracer.Layout.new(8, 1, 2, 2)
      iex> RingTracer.Strategy.Ring.Options.validate([], layout)
      {:ok, [hold_after: 16, aim: true, split: false, part_us: 2000, part_rows: 4, cut_faster: 1.5]}
      iex> RingTracer.Strategy.Ring.Options.validate([aim: false, split: true], layout) |> elem(1) |> Keyword.take([:aim, :split])
      [aim: false, split: true]
      iex> RingTracer.Strategy.Ring.Options.validate([aim: true], RingTracer.Layout.with_frames(layout, 3))
      {:error, "the ring's :aim works within one image, not a sequence of 3 frames"}
      iex> RingTracer.Strategy.Ring.Options.validate([hold: 3], layout)
      {:error, "the ring has no option :hold; its options: [:hold_after, :aim, :split, :part_us, :part_rows, :cut_faster]"}
  """
  @spec validate(keyword(), Layout.t()) :: {:ok, keyword()} | {:error, String.t()}
  def validate(options, %Layout{} = layout) do
    schema = schema(layout)

    with :ok <- known(options, Keyword.keys(schema)) do
      Enum.reduce_while(schema, {:ok, []}, fn {key, {check, what, default}}, {:ok, acc} ->
        value = Keyword.get(options, key, default)

        if check.(value),
          do: {:cont, {:ok, acc ++ [{key, value}]}},
          else:
            {:halt,
             {:error, "the ring's #{inspect(key)} must be #{what}, got: #{inspect(value)}"}}
      end)
      |> one_image(layout)
    end
  end

  # Each option: its check, what the check asks for, its default.
  defp schema(layout) do
    [
      hold_after:
        {&(is_integer(&1) and &1 > 0), "a positive integer", HelpOffer.default_hold_after()},
      aim: {&is_boolean/1, "a boolean", layout.order == :strips and layout.frames == 1},
      split: {&is_boolean/1, "a boolean", false},
      part_us: {&non_neg?/1, "a non-negative number", 2_000},
      part_rows: {&non_neg?/1, "a non-negative number", 4},
      cut_faster: {&non_neg?/1, "a non-negative number", HelpOffer.default_cut_faster()}
    ]
  end

  defp non_neg?(v), do: is_number(v) and v >= 0

  defp known(options, keys) do
    case Keyword.keys(options) -- keys do
      [] ->
        :ok

      [key | _] ->
        {:error, "the ring has no option #{inspect(key)}; its options: #{inspect(keys)}"}
    end
  end

  defp one_image({:ok, options}, %Layout{frames: frames}) when frames > 1 do
    if options[:aim],
      do: {:error, "the ring's :aim works within one image, not a sequence of #{frames} frames"},
      else: {:ok, options}
  end

  defp one_image(result, _layout), do: result
end
