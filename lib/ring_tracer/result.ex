defmodule RingTracer.Result do
  @moduledoc """
  A finished render: the image as linear RGB and what the job did; or a
  finished sequence (`RingTracer.render_sequence/2`): what the job did, and
  each frame without its pixels, which went to the caller as it completed.

    * `:pixels` — `width * height * 3` native-endian 32-bit floats, row-major
      from the top-left, linear light (write it with `RingTracer.Image`);
      `nil` for a sequence; for a job rendered with `pixels: :srgb8`
      (`RingTracer.render/2`), `width * height * 3` bytes of 8-bit sRGB;
    * `:pixel_format` — the format of `:pixels`: `:float` (default) or
      `:srgb8`;
    * `:tinted` — with `pixels: :srgb8` and `ownership: true`, the image
      tinted by who traced each atom, as 8-bit sRGB
      (`RingTracer.Report.Ownership`); `nil` otherwise;
    * `:frames` — a sequence's frames (`RingTracer.Frame`, without their
      pixels), in the order they completed; none for one image;
    * `:started_at_us` — when the job's parent started, wall clock
      (`System.system_time(:microsecond)`); the times below count from it;
    * `:elapsed_us` — the makespan: from starting the parent (children
      included) to the moment the parent holds every atom, in microseconds;
    * `:teardown_us` — from then until every child had stopped and reported;
    * `:ideal_us` — total trace work divided by total capacity (see
      `ideal_us/3`);
    * `:children` — one `t:child/0` per child, in ring order: `:index`, `:node`,
      `:speed`, atoms `:own`, `:given`, `:received`, `:splits` (atoms it cut
      in two to give part of one: adaptive atoms, one item more each, so
      `traced == own - given + received + splits`), `:cuts` (of those, cuts of
      the atom being traced, `RingTracer.Job.Pipe.cut/3`), `:handovers` (hand-over
      messages received), `:traced` (atoms and pieces), offers `:offers_sent`, `:offers_passed`
      (offer messages: offers passed on together count once),
      `:offers_consumed` (for `:steal`, requests sent, refused and granted),
      `:grandchild_restarts`, `:busy_us` (wall time its grandchild spent on
      atoms, slowdown included), `:trace_us` (kernel time), `:idle_us`,
      `:first_atom_us` and `:last_atom_us` (from the job's start), `:rays`
      (its ray counters and work units: `rays.work / busy_us` is its speed),
      `:failed` (`nil`, or why it died mid-job);
    * `:atoms` — one map per atom (none for a sequence): `:atom`, `:owner` (the child whose strip
      it is), `:child` (who traced the copy the parent kept), `:start_us`,
      `:end_us`, `:trace_us`;
    * `:events` — protocol events in time order: `:kind` (`:offer`, `:pass`,
      `:give`, `:returned`, `:steal`, `:refuse`), `:from`, `:to`, `:at_us`;
    * `:messages` — messages between the job's processes, counted at the
      sender, by kind (`:result`, `:handover`, `:offer`, `:control`):
      `%{count: n, bytes: b}` (bytes in the external term format);
    * `:rays` — ray counters summed over all atoms: `:eye`, `:eye_hits`,
      `:reflected`, `:refracted`, `:shadow`, and `:work`, the kernel's work
      units (see `RingTracer.Kernel`);
    * `:strategy` — the strategy's name (its module, for one given as
      `{module, options}`); `:strategy_options` — the options it ran with,
      its defaults filled in (the ring's `:aim`: whether its children aimed
      their offers; `RingTracer.render/2`'s `:strategy`); `:layout` —
      `:strips` or `:interleaved` (see `RingTracer.Layout`);
    * `:duplicates` — atom results that arrived after the atom's first one
      (after a failure the parent may hand out again an atom whose pixels
      were still on their way); the first is kept;
    * `:failures` — children that died mid-job: `:child`, `:reason`, `:at_us`
      (their entry in `:children` has `:failed` set and zero counts);
    * `:redone` — atoms handed out again by the parent after a failure;
    * `:nodes` — per node: `:children`, atoms `:traced` there, and
      `:scene_bytes` shipped to it (0 for the parent's own node);
    * `:warnings`, `:warnings_omitted` — the scene's warnings, as in
      `RingTracer.Scene` (see `RingTracer.Scene.Warning`): what parsed but
      may not render as meant. The library never prints them.
  """

  @enforce_keys [:width, :height, :pixels, :elapsed_us, :children, :rays, :settings]
  defstruct [
    :width,
    :height,
    :pixels,
    :started_at_us,
    :elapsed_us,
    :teardown_us,
    :ideal_us,
    :children,
    :atoms,
    :events,
    :messages,
    :rays,
    :settings,
    :strategy,
    strategy_options: [],
    layout: :strips,
    pixel_format: :float,
    tinted: nil,
    duplicates: 0,
    failures: [],
    redone: 0,
    nodes: %{},
    warnings: [],
    warnings_omitted: 0,
    frames: []
  ]

  @typedoc "A protocol event for the timeline (an offer sent, passed, consumed...)."
  @type event :: %{kind: atom(), from: non_neg_integer(), to: term(), at_us: integer()}

  @typedoc "One traced atom: who owns it, who traced it, when (job microseconds)."
  @type atom_record :: %{
          atom: RingTracer.Layout.atom_id(),
          owner: non_neg_integer(),
          child: non_neg_integer(),
          start_us: integer(),
          end_us: integer(),
          trace_us: non_neg_integer()
        }

  @typedoc """
  A child's statistics, as above (`:idle_us` is set once the job's
  makespan is known).
  """
  @type child :: RingTracer.Job.Stats.t()

  @typedoc "A child that died mid-job: when (microseconds since the parent started), and why."
  @type failure :: %{child: non_neg_integer(), reason: String.t(), at_us: integer()}

  @typedoc "Per node: children placed there, atoms traced there, scene bytes shipped to it."
  @type node_summary :: %{
          children: non_neg_integer(),
          traced: non_neg_integer(),
          scene_bytes: non_neg_integer()
        }

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          pixels: binary() | nil,
          started_at_us: integer() | nil,
          elapsed_us: non_neg_integer(),
          teardown_us: non_neg_integer(),
          ideal_us: non_neg_integer(),
          children: [child()],
          atoms: [atom_record()],
          events: [event()],
          messages: %{atom() => %{count: non_neg_integer(), bytes: non_neg_integer()}},
          rays: map(),
          settings: RingTracer.Settings.t(),
          strategy: atom(),
          strategy_options: keyword(),
          layout: RingTracer.Layout.order(),
          pixel_format: :float | :srgb8,
          tinted: binary() | nil,
          duplicates: non_neg_integer(),
          failures: [failure()],
          redone: non_neg_integer(),
          nodes: %{node() => node_summary()},
          warnings: [RingTracer.Scene.Warning.t()],
          warnings_omitted: non_neg_integer(),
          frames: [RingTracer.Frame.t()]
        }

  @doc false
  @spec new(RingTracer.Settings.t(), {atom(), keyword()}, number(), RingTracer.Job.Parent.reply()) ::
          t()
  def new(settings, {strategy, strategy_options}, capacity_cap, raw) do
    rays = Enum.reduce(raw.children, RingTracer.Rays.zero(), &RingTracer.Rays.add(&2, &1.rays))

    children = Enum.map(raw.children, &%{&1 | idle_us: max(raw.elapsed_us - &1.busy_us, 0)})

    {width, height} = RingTracer.Settings.traced_size(settings)

    %__MODULE__{
      width: width,
      height: height,
      pixels: raw.pixels,
      pixel_format: Map.get(raw, :pixel_format, :float),
      tinted: Map.get(raw, :tinted),
      started_at_us: raw.started_at_us,
      elapsed_us: raw.elapsed_us,
      teardown_us: raw.teardown_us,
      ideal_us: ideal_us(work(raw), Enum.map(children, & &1.speed), capacity_cap),
      children: children,
      atoms: raw.atoms,
      events: raw.events,
      messages: Map.new(raw.traffic, fn {kind, {n, b}} -> {kind, %{count: n, bytes: b}} end),
      rays: rays,
      settings: settings,
      strategy: strategy,
      strategy_options: strategy_options,
      duplicates: raw.duplicates,
      failures: raw.failures,
      redone: raw.redone,
      nodes: raw.nodes,
      layout: raw.layout,
      frames: Map.get(raw, :frames, [])
    }
  end

  # The kept atoms' trace time: from their records, or, in a sequence
  # (whose children keep none), as the parent summed it.
  defp work(%{atoms: [], kept_trace_us: us}), do: us
  defp work(%{atoms: atoms}), do: atoms

  @doc """
  The ideal makespan: total trace work over total capacity. A child of speed
  factor `s` has capacity `1/s`; the total is capped at `cap` (the dirty CPU
  schedulers for the native kernel: no more atoms trace at once than that).

      iex> RingTracer.Result.ideal_us([%{trace_us: 100}, %{trace_us: 300}], [1, 1], 2)
      200
      iex> RingTracer.Result.ideal_us([%{trace_us: 100}, %{trace_us: 300}], [1, 4], 8)
      320
      iex> RingTracer.Result.ideal_us(400, [1, 1], 2)
      200
  """
  @spec ideal_us([map()] | non_neg_integer(), [number()], number()) :: non_neg_integer()
  def ideal_us(work, speeds, cap) when is_integer(work) do
    capacity = min(Enum.reduce(speeds, 0, &(1 / &1 + &2)), cap)
    round(work / capacity)
  end

  def ideal_us(atoms, speeds, cap) do
    work = Enum.reduce(atoms, 0, &(&1.trace_us + &2))
    capacity = min(Enum.reduce(speeds, 0, &(1 / &1 + &2)), cap)
    round(work / capacity)
  end

  @doc "Messages and bytes per atom of the layout (pieces of one atom count once), over all kinds."
  @spec per_atom(t()) :: %{messages: float(), bytes: float()}
  def per_atom(%__MODULE__{messages: messages, atoms: atoms}) do
    n = atoms |> Enum.uniq_by(&RingTracer.Layout.base(&1.atom)) |> length() |> max(1)

    {count, bytes} =
      Enum.reduce(messages, {0, 0}, fn {_, m}, {c, b} -> {c + m.count, b + m.bytes} end)

    %{messages: count / n, bytes: bytes / n}
  end
end

defimpl Inspect, for: RingTracer.Result do
  # One line in iex, not the pixels and every atom's record.
  def inspect(r, _opts) do
    rays = RingTracer.Rays.total(r.rays)
    ms = :erlang.float_to_binary(r.elapsed_us / 1000, decimals: 1)

    failures =
      case r.failures do
        [] -> ""
        f -> ", #{length(f)} failed"
      end

    "#RingTracer.Result<#{r.width}x#{r.height}, #{ms} ms, #{length(r.children)} children " <>
      "(#{r.strategy}), #{length(r.atoms)} atoms, #{rays} rays#{failures}>"
  end
end
