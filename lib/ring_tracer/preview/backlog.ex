defmodule RingTracer.Preview.Backlog do
  @moduledoc false
  # What a preview's queue of a sequence's events (`RingTracer.Preview.Server`,
  # while it paces its work) still needs when an image completes: pure.

  alias RingTracer.Preview.Log

  @typedoc "A queued event, as the server queues it (`{:atom, ...}`, `{:image_done, ...}`...)."
  @type event :: tuple()

  @doc """
  A sequence's image is complete (`done`, the `{:image_done, job, last,
  image}` about to be queued): the atoms still queued of the images
  complete need no drawing (the log would forget them at once), but those
  of the highest complete (what the page shows when none is in flight);
  and of the images complete queued, only those among the `strip` highest
  numbers with `done` keep their pixels (the log's strip is the `strip`
  highest numbers complete, and images complete in about, not exactly,
  their order). So the queue holds at most the images in flight, one
  image complete and `strip` images' pixels. `highest` is the highest
  image complete so far (its index), nil if none. Returns the queue and
  the new `highest`.
  """
  @spec prune(:queue.queue(event()), event(), non_neg_integer() | nil, Log.t()) ::
          {:queue.queue(event()), non_neg_integer() | nil}
  def prune(queue, {:image_done, _, last, image}, highest, %Log{m: m} = log)
      when last != nil and m != nil do
    f = div(RingTracer.Layout.base(last), m)

    {drop, highest} =
      case highest do
        nil -> {nil, f}
        h when f > h -> {h, f}
        h -> {f, h}
      end

    {prune_events(queue, drop, image.number, log), highest}
  end

  def prune(queue, _done, highest, _log), do: {queue, highest}

  defp prune_events(queue, drop, number, %Log{strip: strip, m: m}) do
    events =
      queue
      |> :queue.to_list()
      |> Enum.reject(fn
        {:atom, _, a, _, _, _, _, _} -> drop != nil and div(RingTracer.Layout.base(a), m) == drop
        _ -> false
      end)

    thumbs =
      for({:image_done, _, _, image} <- events, do: image.number)
      |> Enum.concat([number])
      |> Enum.sort(:desc)
      |> Enum.take(strip)
      |> MapSet.new()

    events
    |> Enum.map(fn
      {:image_done, job, l, image} = event ->
        if MapSet.member?(thumbs, image.number),
          do: event,
          else: {:image_done, job, l, %{image | pixels: nil}}

      event ->
        event
    end)
    |> :queue.from_list()
  end
end
