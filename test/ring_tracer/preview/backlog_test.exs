defmodule RingTracer.Preview.BacklogTest do
  use ExUnit.Case, async: true

  alias RingTracer.Preview.{Backlog, Log}

  # Images of 4 atoms; the page's strip keeps 3 thumbnails.
  @m 4
  @log %{Log.new(strip: 3) | m: @m}

  # Image index `f` (scene number f + 1) complete, on its last atom.
  defp done(f),
    do:
      {:image_done, :job, f * @m + @m - 1,
       %{number: f + 1, width: 1, height: 1, pixels: <<f>>, at_us: 0, elapsed_us: 0}}

  defp atom(a), do: {:atom, :job, a, 0, <<a>>, 0, 0, 0}

  defp queue(events), do: :queue.from_list(events)

  defp thumbs(queue),
    do: for({:image_done, _, _, %{number: n, pixels: px}} <- :queue.to_list(queue), px, do: n)

  test "the images queued that stay in the strip (the highest numbers) keep their pixels, whatever their order" do
    # Completed in the order 19, 17, 18 (queued), then 20: the strip is 18,
    # 19, 20, so 19 keeps its thumbnail and 17 loses it.
    q = queue([done(18), done(16), done(17)])
    {q, highest} = Backlog.prune(q, done(19), 18, @log)
    assert highest == 19
    assert Enum.sort(thumbs(q)) == [18, 19]

    # An image completing late, below the strip, keeps every thumbnail.
    q = queue([done(17), done(18), done(19)])
    {q, 19} = Backlog.prune(q, done(15), 19, @log)
    assert Enum.sort(thumbs(q)) == [18, 19, 20]
  end

  test "the atoms queued of an image complete are dropped, but the highest's" do
    q = queue([atom(0), atom(4), done(0), atom(5)])
    # Image 0 completes first: its atoms are what the page shows.
    {^q, 0} = Backlog.prune(q, done(0), nil, @log)
    # Then image 1: image 0's atoms need no drawing any more.
    {q1, 1} = Backlog.prune(q, done(1), 0, @log)
    assert :queue.to_list(q1) == [atom(4), done(0), atom(5)]
    # An image lower than the highest completing late: its own atoms go.
    {q2, 2} = Backlog.prune(queue([atom(4), atom(9)]), done(1), 2, @log)
    assert :queue.to_list(q2) == [atom(9)]
  end

  test "outside a sequence, nothing is dropped" do
    q = queue([atom(0), atom(1)])
    assert Backlog.prune(q, {:image_done, :job, nil, %{number: 1}}, nil, @log) == {q, nil}
    assert Backlog.prune(q, done(0), nil, Log.new()) == {q, nil}
  end
end
