defmodule RingTracer.Report.Timeline do
  @moduledoc false
  # An SVG timeline of a render (`RingTracer.Result`).
  #
  # One horizontal lane per child, labelled `child i (speed s)`, top to bottom
  # in ring order; the x axis is time since the job's start, in milliseconds.
  #
  #   * every atom is a bar (`<rect class="atom">`) from its `start_us` to its
  #     `end_us` in the lane of the child that traced it, filled with the colour
  #     of its original owner (`RingTracer.Report.Palette`); bars traced by a
  #     child other than their owner get a dark outline; hovering shows the
  #     atom, its owner, who traced it and its times;
  #   * protocol events are drawn at their time: `:offer` (solid) and `:pass`
  #     (dashed) as grey arrows from lane `from` to lane `to`, `:steal` requests
  #     as blue arrows, `:give` as red arrows, `:returned` and `:refuse` as a
  #     small mark in lane `from`;
  #   * a header gives the strategy, the makespan, the ideal makespan and their
  #     ratio; a legend explains the marks.
  #
  # Lanes shrink with the number of children (down to 2 px, so 1024 children
  # make a tall but valid SVG); when lanes are too thin for a label each,
  # only every k-th lane is labelled and each lane carries a tooltip instead.

  alias RingTracer.{Error, Result}
  alias RingTracer.Report.Palette

  @plot_width 1200
  @left 170
  @right 30
  @top 78
  @bottom 46
  @max_lane 26.0
  @min_lane 2.0
  @target_plot_height 640.0
  @label_spacing 11.0

  @doc """
  The timeline of `result` as SVG (iodata; `IO.iodata_to_binary/1` gives the
  document).
  """
  @spec svg(Result.t()) :: iodata()
  def svg(%Result{} = result) do
    children = result.children || []
    atoms = result.atoms || []
    events = result.events || []
    n = max(length(children), 1)

    makespan =
      Enum.max(
        [result.elapsed_us || 0, 1] ++
          Enum.map(atoms, & &1.end_us) ++ Enum.map(events, & &1.at_us)
      )

    lane_h = (@target_plot_height / n) |> max(@min_lane) |> min(@max_lane)
    plot_h = lane_h * n
    width = @left + @plot_width + @right
    height = @top + plot_h + @bottom

    geo = %{lane_h: lane_h, makespan: makespan, n: n, plot_h: plot_h}

    [
      ~s(<?xml version="1.0" encoding="UTF-8"?>\n),
      ~s(<svg xmlns="http://www.w3.org/2000/svg" version="1.1" ),
      ~s(width="#{num(width)}" height="#{num(height)}" viewBox="0 0 #{num(width)} #{num(height)}" ),
      ~s(font-family="sans-serif" font-size="12">\n),
      defs(lane_h),
      ~s(<rect x="0" y="0" width="#{num(width)}" height="#{num(height)}" fill="#ffffff"/>\n),
      header(result, makespan),
      legend(n),
      lanes(children, geo),
      axis(geo),
      ~s(<g class="atoms">\n),
      Enum.map(atoms, &atom_bar(&1, geo)),
      ~s(</g>\n<g class="events">\n),
      Enum.map(events, &event_mark(&1, geo)),
      ~s(</g>\n</svg>\n)
    ]
  end

  @doc """
  Writes the timeline of `result` to `path` (an `.svg`), atomically
  (`RingTracer.Output.write/3`, whose options it takes).

  Returns `{:error, %RingTracer.Error{reason: :file}}` for another
  extension or when the file cannot be written.
  """
  @spec write(Result.t(), Path.t(), keyword()) :: :ok | {:error, Error.t()}
  def write(%Result{} = result, path, opts \\ []) when is_binary(path) do
    with :ok <- RingTracer.Output.check_extension(:timeline, path),
         do: RingTracer.Output.write(path, svg(result), opts)
  end

  ## Parts

  # Arrowheads shrink with the lanes (an arrow between neighbouring lanes is
  # one lane long).
  defp defs(lane_h) do
    size = num(lane_h |> Kernel.*(0.5) |> max(2.0) |> min(6.0))

    marker = fn id, fill ->
      [
        ~s(<marker id="#{id}" viewBox="0 0 6 6" refX="6" refY="3" markerWidth="#{size}" ),
        ~s(markerHeight="#{size}" markerUnits="userSpaceOnUse" orient="auto">),
        ~s(<path d="M0,0 L6,3 L0,6 z" fill="#{fill}"/></marker>\n)
      ]
    end

    [
      "<defs>\n",
      marker.("arrow-offer", "#777777"),
      marker.("arrow-give", "#d62728"),
      marker.("arrow-steal", "#1f5fbf"),
      "</defs>\n"
    ]
  end

  defp header(result, makespan) do
    ideal = result.ideal_us || 0

    ratio = if ideal > 0, do: :erlang.float_to_binary(makespan / ideal, decimals: 2), else: "n/a"

    text =
      "strategy #{result.strategy} | #{length(result.children || [])} children, " <>
        "#{length(result.atoms || [])} atoms | makespan #{ms(makespan)} ms | " <>
        "ideal #{ms(ideal)} ms | makespan/ideal #{ratio}"

    [
      ~s(<text class="header" x="#{@left}" y="22" font-size="15" font-weight="bold">),
      escape(text),
      "</text>\n"
    ]
  end

  defp legend(n) do
    y = 44
    shown = min(n, 12)

    swatches =
      for i <- 0..(shown - 1)//1 do
        x = @left + i * 58

        [
          ~s(<rect x="#{x}" y="#{y - 9}" width="10" height="10" fill="#{Palette.hex(i)}"/>),
          ~s(<text x="#{x + 13}" y="#{y}" font-size="10">child #{i}</text>\n)
        ]
      end

    more =
      if n > shown,
        do: [
          ~s(<text x="#{@left + shown * 58}" y="#{y}" font-size="10">),
          escape("... (#{n} children, golden-angle hues)"),
          "</text>\n"
        ],
        else: []

    y2 = 62
    x0 = @left

    marks = [
      ~s(<text x="#{x0}" y="#{y2}" font-size="10">bar colour = original owner; outlined = traced by another child</text>\n),
      arrow_line(x0 + 380, y2 - 4, x0 + 410, y2 - 4, :offer),
      ~s(<text x="#{x0 + 415}" y="#{y2}" font-size="10">offer</text>\n),
      arrow_line(x0 + 450, y2 - 4, x0 + 480, y2 - 4, :pass),
      ~s(<text x="#{x0 + 485}" y="#{y2}" font-size="10">pass</text>\n),
      arrow_line(x0 + 520, y2 - 4, x0 + 550, y2 - 4, :give),
      ~s(<text x="#{x0 + 555}" y="#{y2}" font-size="10">give</text>\n),
      arrow_line(x0 + 590, y2 - 4, x0 + 620, y2 - 4, :steal),
      ~s(<text x="#{x0 + 625}" y="#{y2}" font-size="10">steal</text>\n),
      small_mark(x0 + 670, y2 - 4, 4.0, :returned),
      ~s(<text x="#{x0 + 678}" y="#{y2}" font-size="10">returned</text>\n),
      small_mark(x0 + 735, y2 - 4, 4.0, :refuse),
      ~s(<text x="#{x0 + 743}" y="#{y2}" font-size="10">refuse</text>\n)
    ]

    [~s(<g class="legend">\n), swatches, more, marks, "</g>\n"]
  end

  defp lanes(children, geo) do
    %{lane_h: lane_h} = geo
    every = max(1, ceil(@label_spacing / lane_h))
    font = lane_h |> Kernel.*(0.7) |> min(12.0) |> max(9.0)

    rows =
      children
      |> Enum.with_index()
      |> Enum.map(fn {child, row} ->
        y = @top + row * lane_h
        label = "child #{child.index} (speed #{format_speed(child.speed)})"
        fill = if rem(row, 2) == 0, do: "#f4f4f4", else: "#e8e8e8"

        text =
          if rem(row, every) == 0 do
            [
              ~s(<text x="#{@left - 6}" y="#{num(y + lane_h / 2)}" ),
              ~s(font-size="#{num(font)}" text-anchor="end" dominant-baseline="middle">),
              escape(label),
              "</text>"
            ]
          else
            []
          end

        [
          ~s(<rect class="lane" x="#{@left}" y="#{num(y)}" width="#{@plot_width}" height="#{num(lane_h)}" fill="#{fill}">),
          "<title>",
          escape(label),
          "</title></rect>",
          text,
          "\n"
        ]
      end)

    [~s(<g class="lanes">\n), rows, "</g>\n"]
  end

  defp axis(%{makespan: makespan, plot_h: plot_h}) do
    y = @top + plot_h
    step = tick_step(makespan / 1000)

    ticks =
      Stream.iterate(0.0, &(&1 + step))
      |> Enum.take_while(&(&1 * 1000 <= makespan * 1.0000001))
      |> Enum.map(fn t_ms ->
        x = x_of(t_ms * 1000, makespan)

        [
          ~s(<line x1="#{num(x)}" y1="#{@top}" x2="#{num(x)}" y2="#{num(y + 5)}" stroke="#bbbbbb" stroke-width="0.5"/>),
          ~s(<text x="#{num(x)}" y="#{num(y + 18)}" font-size="10" text-anchor="middle">),
          tick_label(t_ms, step),
          "</text>\n"
        ]
      end)

    [
      ~s(<g class="axis">\n),
      ~s(<line x1="#{@left}" y1="#{num(y)}" x2="#{@left + @plot_width}" y2="#{num(y)}" stroke="#333333"/>\n),
      ticks,
      ~s|<text x="#{@left + div(@plot_width, 2)}" y="#{num(y + 36)}" text-anchor="middle">time (ms)</text>\n|,
      "</g>\n"
    ]
  end

  defp atom_bar(atom, geo) do
    %{lane_h: lane_h, makespan: makespan} = geo
    row = atom.child
    pad = if lane_h >= 6, do: lane_h * 0.12, else: 0.0
    x1 = x_of(atom.start_us, makespan)
    x2 = x_of(atom.end_us, makespan)
    y = @top + row * lane_h + pad

    outline =
      if atom.child != atom.owner and lane_h >= 6,
        do: ~s( stroke="#222222" stroke-width="1"),
        else: ""

    tip =
      "atom #{RingTracer.Layout.name(atom.atom)}: owner child #{atom.owner}, traced by child #{atom.child}, " <>
        "#{ms(atom.start_us)}-#{ms(atom.end_us)} ms (trace #{ms(atom.trace_us || 0)} ms)"

    [
      ~s(<rect class="atom" x="#{num(x1)}" y="#{num(y)}" width="#{num(max(x2 - x1, 0.5))}" ),
      ~s(height="#{num(lane_h - 2 * pad)}" fill="#{Palette.hex(atom.owner)}"#{outline}>),
      "<title>",
      escape(tip),
      "</title></rect>\n"
    ]
  end

  defp event_mark(%{kind: kind, from: from, to: to, at_us: at}, geo)
       when is_integer(from) and is_integer(at) do
    %{lane_h: lane_h, makespan: makespan, n: n} = geo
    x = x_of(at, makespan)
    y_from = lane_mid(from, lane_h)
    tip = escape("#{kind} #{from} -> #{inspect(to)} at #{ms(at)} ms")

    cond do
      from not in 0..(n - 1) ->
        []

      kind in [:returned, :refuse] ->
        [small_mark(x, y_from, min(4.0, max(lane_h / 2, 1.5)), kind, tip), "\n"]

      is_integer(to) and to in 0..(n - 1) ->
        [arrow_line(x, y_from, x, lane_mid(to, lane_h), kind, tip), "\n"]

      true ->
        []
    end
  end

  defp event_mark(_event, _geo), do: []

  defp arrow_line(x1, y1, x2, y2, kind, tip \\ nil) do
    {stroke, marker, dash} =
      case kind do
        :give -> {"#d62728", "arrow-give", ""}
        :steal -> {"#1f5fbf", "arrow-steal", ""}
        :pass -> {"#777777", "arrow-offer", ~s( stroke-dasharray="3,2")}
        _ -> {"#777777", "arrow-offer", ""}
      end

    width = if kind == :give, do: "1.2", else: "0.8"

    [
      ~s(<line class="event #{kind}" x1="#{num(x1)}" y1="#{num(y1)}" x2="#{num(x2)}" y2="#{num(y2)}" ),
      ~s|stroke="#{stroke}" stroke-width="#{width}"#{dash} marker-end="url(##{marker})">|,
      title(tip),
      "</line>"
    ]
  end

  defp small_mark(x, y, r, kind, tip \\ nil) do
    colour = if kind == :refuse, do: "#1f5fbf", else: "#2ca02c"

    [
      ~s(<circle class="event #{kind}" cx="#{num(x)}" cy="#{num(y)}" r="#{num(r)}" ),
      ~s(fill="none" stroke="#{colour}" stroke-width="1">),
      title(tip),
      "</circle>"
    ]
  end

  defp title(nil), do: []
  defp title(tip), do: ["<title>", tip, "</title>"]

  ## Helpers

  defp x_of(us, makespan), do: @left + us / makespan * @plot_width
  defp lane_mid(row, lane_h), do: @top + (row + 0.5) * lane_h

  # A "nice" tick step (1, 2 or 5 times a power of ten) giving about 10 ticks.
  defp tick_step(span_ms) when span_ms <= 0, do: 1.0

  defp tick_step(span_ms) do
    raw = span_ms / 10
    mag = :math.pow(10, Float.floor(:math.log10(raw)))

    Enum.find([1, 2, 5, 10], &(&1 * mag >= raw)) * mag
  end

  defp tick_label(t_ms, step) do
    decimals = step |> :math.log10() |> Float.floor() |> trunc() |> Kernel.-() |> max(0)
    :erlang.float_to_binary(t_ms * 1.0, decimals: decimals)
  end

  defp format_speed(s) when is_float(s), do: :erlang.float_to_binary(s, [:compact, decimals: 3])
  defp format_speed(s), do: to_string(s)

  defp ms(us), do: :erlang.float_to_binary(us / 1000, decimals: 2)

  defp num(x) when is_integer(x), do: Integer.to_string(x)
  defp num(x) when is_float(x), do: :erlang.float_to_binary(x, [:compact, decimals: 2])

  defp escape(text) do
    text
    |> to_string()
    |> String.replace("&", "&amp;")
    |> String.replace("<", "&lt;")
    |> String.replace(">", "&gt;")
    |> String.replace("\"", "&quot;")
    |> String.replace("'", "&apos;")
  end
end
