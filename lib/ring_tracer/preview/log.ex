defmodule RingTracer.Preview.Log do
  @moduledoc """
  The event log of one previewed job: what a browser needs to draw the job
  from its start, as Server-Sent Events frames, numbered in order.

  A viewer reads the frames after the last one it sent, so a late joiner
  gets everything so far and a slow one only lags: nothing is buffered per
  viewer. The log is bounded by the image: one frame per atom (its pixels
  as 8-bit sRGB, base64), one per hand-over of atoms, protocol events up
  to `max_events` (later ones are counted, not kept; the final frame has
  every event), and the job and final frames.

  Frames (`event:` name, `data:` one JSON object):

    * `job` — `width`, `height`, `children`, `total` atoms, `strategy`,
      `nodes` and `speeds` per child, `palette` (the colour of each child,
      as in `RingTracer.Report.Palette`), `owners` and `spans`
      (`[first_pixel, count]`) per atom
    * `atom` — `a` atom, `c` child that traced it, `at` µs since the job's
      start when it reached the parent, `tus` trace µs, `rays`, `px` its
      pixels (3 bytes a pixel, sRGB, base64)
    * `ev` — a protocol event of a child: `kind` (`offer`, `pass`, `give`,
      `back`, `returned`, `steal`, `refuse`), `from`, `to`, `at`
    * `move` — atoms handed over: `from` (a child or `parent`), `to`, `n`,
      `at`
    * `final` — the job's statistics (`elapsed_us`, `children`, `traffic`,
      `atoms` with their exact times, `events`...), or `error`
    * `end` — the stream ends
  """

  alias RingTracer.Layout
  alias RingTracer.Report.Palette

  defstruct seq: 0,
            frames: [],
            job: nil,
            t0: 0,
            atoms: MapSet.new(),
            events: 0,
            dropped: 0,
            max_events: 10_000,
            done: false

  @type t :: %__MODULE__{}
  @type frame :: {pos_integer(), binary()}

  @doc "An empty log that keeps at most `max_events` protocol events."
  @spec new(keyword()) :: t()
  def new(opts \\ []), do: %__MODULE__{max_events: Keyword.get(opts, :max_events, 10_000)}

  @doc """
  Takes the frames appended since the last call, oldest first, and leaves
  the log without them (the caller stores them).
  """
  @spec take(t()) :: {[frame()], t()}
  def take(log), do: {Enum.reverse(log.frames), %{log | frames: []}}

  @doc """
  Starts the log with the job's description (`RingTracer.Job.Parent`'s
  `describe`): its layout, the node and speed of each child, its start
  time, and the atoms traced so far (`results`, `traced_by`).
  """
  @spec job(t(), map()) :: t()
  def job(%__MODULE__{job: nil} = log, info) do
    layout = info.layout
    n = layout.children
    atoms = Layout.atoms(layout)

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
      spans: Enum.map(atoms, &Tuple.to_list(Layout.span(layout, &1)))
    }

    log = append(%{log | job: info.id, t0: info.t0}, "job", data)

    info.results
    |> Enum.sort()
    |> Enum.reduce(log, fn {a, pixels}, acc ->
      atom(acc, a, Map.fetch!(info.traced_by, a), pixels, 0, 0, nil)
    end)
  end

  @doc """
  An atom's pixels (linear RGB floats, as the parent gets them) reached the
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
          px_base64(pixels),
          ~s("})
        ])

      append(%{log | atoms: MapSet.put(log.atoms, a)}, "atom", data)
    end
  end

  # 4096 pixels of 3 floats: a piece of the NIF's (on a normal scheduler,
  # never taking a dirty one from the job's atoms), a multiple of 3 bytes of
  # sRGB, so the pieces' base64 texts concatenate.
  @piece_bytes 4096 * 12

  defp px_base64(<<piece::binary-size(@piece_bytes), rest::binary>>),
    do: [base64(piece) | px_base64(rest)]

  defp px_base64(<<>>), do: []
  defp px_base64(piece), do: [base64(piece)]

  defp base64(piece) do
    {:ok, text} = RingTracer.Native.to_srgb8_base64(piece)
    text
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

    log |> append("final", data) |> close()
  end

  def final(log, {:error, message}),
    do: log |> append("final", %{ok: false, error: to_string(message)}) |> close()

  @doc "The job went away without a reply (cancelled, or its parent died)."
  @spec gone(t(), term()) :: t()
  def gone(%__MODULE__{done: true} = log, _reason), do: log

  def gone(log, reason),
    do:
      log |> append("final", %{ok: false, error: "the job ended: #{inspect(reason)}"}) |> close()

  defp close(log), do: %{append(log, "end", %{}) | done: true}

  defp child_stats(s) do
    rays = Map.new(s.rays, fn {k, v} -> {k, v} end)

    s
    |> Map.take(
      [:index, :speed, :own, :given, :received, :handovers, :traced, :offers_sent] ++
        [:offers_passed, :offers_consumed, :grandchild_restarts, :busy_us, :trace_us]
    )
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
