defmodule RingTracer.Preview.Log do
  @moduledoc false
  # The event log of one previewed job: what a browser needs to draw the job
  # from its start, as Server-Sent Events frames, numbered in order.
  #
  # A viewer reads the frames after the last one it sent, so a late joiner
  # gets everything so far and a slow one only lags: nothing is buffered per
  # viewer. The log is bounded by the image: one frame per atom (its pixels
  # as 8-bit sRGB, base64), one per hand-over of atoms, protocol events up
  # to `max_events` (later ones are counted, not kept; the final frame has
  # every event), and the job and final frames.
  #
  # A sequence (`RingTracer.render_sequence/2`: a layout of several frames,
  # or any frame event) is bounded by its window instead of its length: the
  # log forgets (`forget/1` gives the numbers of the frames to delete) the
  # `release` and `atom` frames of an image once it is complete, but those of
  # the image complete with the highest number (what the page shows when no
  # image is in flight), keeps the `frame` frames of the `strip` images
  # complete with the highest numbers (12 by default: images complete in
  # about their order, so those completed last) and the newest `frame` frame
  # (the count complete and the images in flight, for a page that lagged),
  # counts hand-overs with the protocol events against `max_events`, and its
  # final frame has the atoms and events of the last `strip` images only. What stays: the job frame, the images in flight,
  # one image completed, `strip` thumbnails, at most `max_events` events.
  #
  # Frames (`event:` name, `data:` one JSON object):
  #
  #   * `job` — `width`, `height`, `children`, `total` atoms, `strategy`,
  #     `nodes` and `speeds` per child, `palette` (the colour of each child,
  #     as in `RingTracer.Report.Palette`), `owners` and `spans`
  #     (`[first_pixel, count]`) per atom of one image (`m` of them: atom
  #     `a` is atom `a mod m` of image `a div m`), `frames` (images in the
  #     job: 1 but for a sequence), `strip` (thumbnails kept)
  #   * `atom` — `a` atom, `c` child that traced it, `at` µs since the job's
  #     start when it reached the parent, `tus` trace µs, `rays`, `px` its
  #     pixels (3 bytes a pixel, sRGB, base64)
  #   * `release` — a sequence released an image: `f` its index in the job
  #     (from 0; `null` when the preview opened on a running sequence), `n`
  #     its frame number in the scene, `at` µs since the job's start
  #   * `frame` — a sequence's image is complete: `f` (`null` if unknown),
  #     `n`, `at`, `us` from its release to its last pixel, `completed`
  #     images so far, `mean_us` the mean `us` of those the preview saw
  #     complete, and its thumbnail: `tw`,
  #     `th`, `px` (sRGB, base64, as an atom's; `null` when the preview was
  #     too far behind to keep it), `flight` the indices of the images still
  #     in flight (a viewer that lagged may have missed the `frame` frames,
  #     since forgotten, of others)
  #   * `ev` — a protocol event of a child: `kind` (`offer`, `pass`, `give`,
  #     `back`, `returned`, `steal`, `refuse`), `from`, `to`, `at`
  #   * `move` — atoms handed over: `from` (a child or `parent`), `to`, `n`,
  #     `at`
  #   * `final` — the job's statistics (`elapsed_us`, `children`, `traffic`,
  #     `atoms` with their exact times, `events`...), or `error`
  #   * `end` — the stream ends

  alias RingTracer.{Layout, Pixels}
  alias RingTracer.Report.Palette

  defstruct seq: 0,
            frames: [],
            job: nil,
            format: :float,
            t0: 0,
            atoms: MapSet.new(),
            events: 0,
            dropped: 0,
            max_events: 10_000,
            done: false,
            # a sequence's
            sequence: false,
            m: nil,
            images: 1,
            strip: 12,
            next: nil,
            flight: %{},
            held: {0, []},
            thumbs: [],
            newest: nil,
            unindexed: %{},
            completed: 0,
            timed: 0,
            sum_us: 0,
            forget: []

  @typedoc """
  The log. For a sequence: `m` atoms an image, `images` in the job, `next`
  index to be released (nil: unknown), `flight` the log's frames of each
  image in flight by index (`unindexed`: by number, the `release` frames
  of an index unknown), `held` those of the image completed with the
  highest number (and that number), `thumbs` the `frame` frames kept (at
  most `strip`, `{number, seq}`, by number; `newest` the latest `frame`
  frame when it is not one of them), `completed` images
  (`timed` of them seen complete, and the sum of their times), `forget` the
  frames to delete.
  """
  @type t :: %__MODULE__{}
  @type frame :: {pos_integer(), binary()}

  @typedoc """
  A sequence's image, complete: its number, times (job µs), and its
  pixels (`RingTracer.Frame`'s, or nil, in `pixel_format`) to make the
  thumbnail from.
  """
  @type image :: %{
          number: pos_integer(),
          width: pos_integer(),
          height: pos_integer(),
          pixels: binary() | nil,
          pixel_format: RingTracer.Pixels.format(),
          at_us: integer(),
          elapsed_us: non_neg_integer()
        }

  # The thumbnails' longer side, in pixels, at most.
  @thumb 96

  @doc """
  An empty log that keeps at most `max_events` protocol events and, of a
  sequence, `strip` thumbnails.
  """
  @spec new(keyword()) :: t()
  def new(opts \\ []),
    do: %__MODULE__{
      max_events: Keyword.get(opts, :max_events, 10_000),
      strip: Keyword.get(opts, :strip, 12)
    }

  @doc """
  Takes the frames appended since the last call, oldest first, and leaves
  the log without them (the caller stores them).
  """
  @spec take(t()) :: {[frame()], t()}
  def take(log), do: {Enum.reverse(log.frames), %{log | frames: []}}

  @doc """
  Takes the numbers of the frames a sequence no longer needs, and leaves
  the log without them (the caller deletes those frames).
  """
  @spec forget(t()) :: {[pos_integer()], t()}
  def forget(log), do: {log.forget, %{log | forget: []}}

  @doc """
  Starts the log with the job's description (`RingTracer.Job.Parent`'s
  `describe`): its layout, the node and speed of each child, its start
  time, and the atoms traced so far (`results`, in `format`, `traced_by`;
  of a sequence, the oldest image in flight's). `from_start: true` when the
  log has every event of the job (the preview was there before it
  started): then a sequence's images are numbered from its first release.
  """
  @spec job(t(), map()) :: t()
  def job(%__MODULE__{job: nil} = log, info) do
    layout = info.layout
    n = layout.children
    m = Layout.frame_atom_count(layout)
    atoms = Layout.frame_atoms(layout, 0)

    data = %{
      width: layout.width,
      height: layout.height,
      children: n,
      total: Layout.atom_count(layout),
      strategy: strategy_name(info.strategy),
      nodes: Enum.map(info.nodes, &Atom.to_string/1),
      speeds: info.speeds,
      palette: Enum.map(0..(n - 1), &Palette.hex/1),
      owners: Enum.map(atoms, &Layout.owner(layout, &1)),
      spans: Enum.map(atoms, &Tuple.to_list(Layout.span(layout, &1))),
      m: m,
      frames: layout.frames,
      strip: log.strip
    }

    # Opened on a running sequence: the images before the oldest in flight
    # are complete.
    traced = Map.keys(info.results) ++ Map.keys(info.traced_by)
    from_start = Map.get(info, :from_start, false)

    log = %{
      log
      | job: info.id,
        format: Map.get(info, :format, :float),
        t0: info.t0,
        m: m,
        images: layout.frames,
        sequence: layout.frames > 1,
        next: if(from_start, do: 0),
        completed:
          if(from_start or traced == [],
            do: 0,
            else: traced |> Enum.map(&image(m, &1)) |> Enum.min()
          )
    }

    log = append(log, "job", data)

    info.results
    |> Enum.sort()
    |> Enum.reduce(log, fn {a, pixels}, acc ->
      atom(acc, a, Map.fetch!(info.traced_by, a), pixels, 0, 0, nil)
    end)
  end

  @doc """
  An atom's pixels (in the job's format, as the parent decoded them) reached the
  parent at wall-clock µs `at` (`nil`: unknown, before the preview opened).
  A second copy of an atom is ignored.
  """
  @spec atom(
          t(),
          Layout.atom_id(),
          non_neg_integer(),
          binary(),
          non_neg_integer(),
          non_neg_integer(),
          integer() | nil
        ) :: t()
  def atom(%__MODULE__{done: true} = log, _a, _c, _px, _rays, _us, _at), do: log

  def atom(log, a, child, pixels, rays, trace_us, at) do
    if MapSet.member?(log.atoms, a) do
      log
    else
      # Built by hand: the pixels are base64 already, so no JSON encoder
      # needs to scan the longest part of the frame.
      at = if at, do: Integer.to_string(at - log.t0), else: "null"

      data =
        IO.iodata_to_binary([
          ~s({"a":),
          Integer.to_string(Layout.base(a)),
          piece_field(a),
          ~s(,"c":),
          Integer.to_string(child),
          ~s(,"at":),
          at,
          ~s(,"tus":),
          Integer.to_string(trace_us),
          ~s(,"rays":),
          Integer.to_string(rays),
          ~s(,"px":"),
          px_base64(pixels, log.format),
          ~s("})
        ])

      %{log | atoms: MapSet.put(log.atoms, a)}
      |> append("atom", data)
      |> in_flight(image(log.m, a))
    end
  end

  @doc """
  A sequence released image number `number` (in the scene, from 1) at job
  µs `at`.
  """
  @spec release(t(), pos_integer(), integer()) :: t()
  def release(%__MODULE__{done: true} = log, _number, _at), do: log

  def release(log, number, at) do
    f = log.next
    log = append(%{log | sequence: true}, "release", %{f: f, n: number, at: at})

    if f,
      do: %{in_flight(log, f) | next: f + 1},
      else: %{log | unindexed: Map.put(log.unindexed, number, log.seq)}
  end

  @doc """
  A sequence's image is complete (`image()`); `last` is the last atom
  that reached the parent before it (one of this image's: the parent
  completes an image on its last atom), nil if none. Its thumbnail (at
  most #{@thumb} pixels a side, nearest pixels) is made here.
  """
  @spec image_done(t(), Layout.atom_id() | nil, image()) :: t()
  def image_done(%__MODULE__{done: true} = log, _last, _image), do: log

  def image_done(log, last, image) do
    f = if last != nil and log.m, do: image(log.m, last)
    completed = log.completed + 1
    timed = log.timed + 1
    sum = log.sum_us + image.elapsed_us
    {tw, th, px} = thumbnail(image)
    {seqs, flight} = Map.pop(log.flight, f, [])
    {release, unindexed} = Map.pop(log.unindexed, image.number)
    seqs = if release, do: [release | seqs], else: seqs

    data =
      IO.iodata_to_binary([
        ~s({"f":),
        json_int(f),
        ~s(,"n":),
        Integer.to_string(image.number),
        ~s(,"at":),
        Integer.to_string(image.at_us),
        ~s(,"us":),
        Integer.to_string(image.elapsed_us),
        ~s(,"completed":),
        Integer.to_string(completed),
        ~s(,"mean_us":),
        Integer.to_string(div(sum, timed)),
        ~s(,"tw":),
        Integer.to_string(tw),
        ~s(,"th":),
        Integer.to_string(th),
        ~s(,"px":),
        if(px, do: [?", px, ?"], else: "null"),
        ~s(,"flight":[),
        flight |> Map.keys() |> Enum.sort() |> Enum.map(&Integer.to_string/1) |> Enum.join(","),
        "]}"
      ])

    log =
      append(
        %{log | sequence: true, completed: completed, timed: timed, sum_us: sum},
        "frame",
        data
      )

    # The strip: the `strip` highest numbers complete (images complete in
    # about their order: those completed last).
    thumbs = Enum.sort([{image.number, log.seq} | log.thumbs])

    {old, thumbs} =
      if length(thumbs) > log.strip,
        do: {[elem(hd(thumbs), 1)], tl(thumbs)},
        else: {[], thumbs}

    # The newest `frame` frame stays until the next one, in the strip or not:
    # it has the count complete and the images in flight, which a page that
    # lagged past the others' needs (the image completed last may have the
    # lowest number, and then no later `frame` frame would tell the page).
    {old, newest} = if old == [log.seq], do: {[], log.seq}, else: {old, nil}
    old = List.wrap(log.newest) ++ old

    # The image shown when none is in flight: the highest number complete.
    {held, gone} =
      case log.held do
        {n, old_seqs} when image.number > n -> {{image.number, seqs}, old_seqs}
        held -> {held, seqs}
      end

    atoms = if f, do: MapSet.reject(log.atoms, &(image(log.m, &1) == f)), else: log.atoms

    %{
      log
      | flight: flight,
        unindexed: unindexed,
        held: held,
        thumbs: thumbs,
        newest: newest,
        atoms: atoms,
        forget: old ++ gone ++ log.forget
    }
  end

  # The log's frames of image `f` (nil: unknown), to forget when it completes.
  defp in_flight(%__MODULE__{sequence: true} = log, f) when f != nil,
    do: %{log | flight: Map.update(log.flight, f, [log.seq], &[log.seq | &1])}

  defp in_flight(log, _f), do: log

  defp image(nil, _a), do: nil
  defp image(m, a), do: div(Layout.base(a), m)

  defp json_int(nil), do: "null"
  defp json_int(n), do: Integer.to_string(n)

  @doc """
  An image's thumbnail, `{width, height, sRGB base64}`: its nearest pixels
  at most #{@thumb} a side (`{w, h, nil}` without pixels).
  """
  @spec thumbnail(%{
          required(:width) => pos_integer(),
          required(:height) => pos_integer(),
          required(:pixels) => binary() | nil,
          optional(:pixel_format) => RingTracer.Pixels.format(),
          optional(atom()) => term()
        }) ::
          {pos_integer(), pos_integer(), binary() | nil}
  def thumbnail(%{width: w, height: h, pixels: px} = image) do
    format = Map.get(image, :pixel_format, :float)
    scale = min(1.0, @thumb / max(w, h))
    {tw, th} = {max(1, round(w * scale)), max(1, round(h * scale))}

    cond do
      px == nil or byte_size(px) != Pixels.size(w * h, format) ->
        {tw, th, nil}

      {tw, th} == {w, h} ->
        {w, h, IO.iodata_to_binary(px_base64(px, format))}

      true ->
        sampled =
          for ty <- 0..(th - 1), tx <- 0..(tw - 1), into: <<>> do
            y = div((2 * ty + 1) * h, 2 * th)
            x = div((2 * tx + 1) * w, 2 * tw)
            Pixels.slice(px, format, y * w + x, 1)
          end

        {tw, th, IO.iodata_to_binary(px_base64(sampled, format))}
    end
  end

  # Pieces of 4096 pixels: the NIF's (on a normal scheduler, never taking a
  # dirty one from the job's atoms), a multiple of 3 bytes of sRGB, so the
  # pieces' base64 texts concatenate.
  @piece_pixels 4096

  defp px_base64(pixels, format) do
    bytes = Pixels.size(@piece_pixels, format)

    case pixels do
      <<piece::binary-size(bytes), rest::binary>> ->
        [Pixels.srgb8_base64(piece, format) | px_base64(rest, format)]

      <<>> ->
        []

      piece ->
        [Pixels.srgb8_base64(piece, format)]
    end
  end

  @doc "A child's protocol event (its `at_us` is already job time)."
  @spec event(t(), atom(), non_neg_integer(), term(), integer()) :: t()
  def event(%__MODULE__{done: true} = log, _kind, _from, _to, _at), do: log

  def event(%__MODULE__{events: n, max_events: max} = log, _kind, _from, _to, _at)
      when n >= max,
      do: %{log | dropped: log.dropped + 1}

  def event(log, kind, from, to, at) do
    data = %{kind: kind, from: from, to: json_term(to), at: at}
    append(%{log | events: log.events + 1}, "ev", data)
  end

  @doc "Atoms handed over from `from` (a child, or `:parent`) to child `to`, at wall-clock µs `at`."
  @spec move(t(), non_neg_integer() | :parent, non_neg_integer(), non_neg_integer(), integer()) ::
          t()
  def move(%__MODULE__{done: true} = log, _from, _to, _n, _at), do: log

  # A sequence's hand-overs grow with its length: they count with the events.
  def move(%__MODULE__{sequence: true, events: n, max_events: max} = log, _from, _to, _n, _at)
      when n >= max,
      do: %{log | dropped: log.dropped + 1}

  def move(%__MODULE__{sequence: true} = log, from, to, n, at),
    do:
      append(%{log | events: log.events + 1}, "move", %{
        from: json_term(from),
        to: to,
        n: n,
        at: at - log.t0
      })

  def move(log, from, to, n, at),
    do: append(log, "move", %{from: json_term(from), to: to, n: n, at: at - log.t0})

  @doc """
  The job ended: `{:ok, raw}` (the parent's reply: statistics, atoms,
  events) or `{:error, message}`; then the stream's end. Later calls are
  ignored.
  """
  @spec final(t(), {:ok, map()} | {:error, term()}) :: t()
  def final(%__MODULE__{done: true} = log, _reply), do: log

  def final(log, {:ok, raw}) do
    data = %{
      ok: true,
      elapsed_us: raw.elapsed_us,
      teardown_us: raw.teardown_us,
      duplicates: raw.duplicates,
      redone: raw.redone,
      dropped_events: log.dropped,
      traffic: Map.new(raw.traffic, fn {k, {n, b}} -> {k, %{n: n, bytes: b}} end),
      children: Enum.map(raw.children, &child_stats/1),
      atoms: Enum.map(raw.atoms, &Map.take(&1, [:atom, :owner, :child, :start_us, :end_us])),
      events: Enum.map(raw.events, &%{&1 | to: json_term(&1.to)})
    }

    log |> append("final", sequence_final(log, data, raw)) |> close()
  end

  def final(log, {:error, message}),
    do: log |> append("final", %{ok: false, error: to_string(message)}) |> close()

  @doc "The job went away without a reply (cancelled, or its parent died)."
  @spec gone(t(), term()) :: t()
  def gone(%__MODULE__{done: true} = log, _reason), do: log

  def gone(log, reason),
    do:
      log |> append("final", %{ok: false, error: "the job ended: #{inspect(reason)}"}) |> close()

  # A sequence's final frame: the atoms of its last `strip` images, the
  # events from the first of those on (at most `max_events`, the latest),
  # and its images' count and mean time.
  defp sequence_final(%__MODULE__{sequence: false}, data, _raw), do: data

  defp sequence_final(log, data, raw) do
    first = max(log.images - log.strip, 0) * log.m
    atoms = Enum.filter(data.atoms, &(Layout.base(&1.atom) >= first))
    since = atoms |> Enum.map(& &1.start_us) |> Enum.min(fn -> 0 end)
    events = data.events |> Enum.filter(&(&1.at_us >= since)) |> Enum.take(-log.max_events)
    times = Enum.map(Map.get(raw, :frames, []), &RingTracer.Frame.elapsed_us/1)

    Map.merge(data, %{
      atoms: atoms,
      events: events,
      frames: length(times),
      mean_us: if(times == [], do: 0, else: div(Enum.sum(times), length(times)))
    })
  end

  defp close(log), do: %{append(log, "end", %{}) | done: true}

  defp child_stats(s) do
    rays = Map.new(s.rays, fn {k, v} -> {k, v} end)

    s
    |> Map.take(RingTracer.Job.Stats.columns())
    |> Map.put(:node, if(s.node, do: Atom.to_string(s.node), else: nil))
    |> Map.put(:rays, rays)
    |> Map.put(:failed, Map.get(s, :failed))
  end

  defp json_term(t) when is_integer(t) or is_binary(t) or is_nil(t), do: t
  defp json_term(t) when is_atom(t), do: Atom.to_string(t)
  defp json_term(t), do: inspect(t)

  defp append(log, name, data) do
    seq = log.seq + 1

    json = if is_binary(data), do: data, else: :jiffy.encode(data, [:use_nil])
    frame = IO.iodata_to_binary(["event: ", name, "\ndata: ", json, "\n\n"])

    %{log | seq: seq, frames: [{seq, frame} | log.frames]}
  end

  # `{RingTracer.Strategy.Ring, opts}` reads "Ring"; a strategy of one's own, its module.
  defp strategy_name({module, _opts}), do: strategy_name(module)

  defp strategy_name(module) when is_atom(module),
    do: String.replace_prefix(inspect(module), "RingTracer.Strategy.", "")

  defp strategy_name(other), do: inspect(other)

  # A piece of an atom (adaptive atoms): its parts `lo` to `hi` of `d`.
  defp piece_field({_a, lo, hi, d}), do: ~s(,"p":[#{lo},#{hi},#{d}])
  defp piece_field(_atom), do: []
end
