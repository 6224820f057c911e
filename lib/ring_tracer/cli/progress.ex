defmodule RingTracer.CLI.Progress do
  @moduledoc false
  # What a render shows while it runs, on stderr.
  #
  #   * On a terminal (`:tty`): a bar redrawn every 100 ms with atoms done,
  #     rays per second and the time left. Between atoms it moves by the
  #     expected progress of the atoms being traced (the mean rate so far),
  #     never past what could be done, so a ring of one child does not jump
  #     in sixteenths.
  #   * Elsewhere (`:log`: a file, a pipe, CI): a plain line every 5 s.
  #   * `:quiet`: nothing.
  #
  # The state is a struct the render command updates with `atom/3` (from
  # `RingTracer.Telemetry`'s `[:ring_tracer, :atom, :stop]`) and `tick/2`;
  # both return the text to write, if any, so the rules are tested without a
  # terminal.
  #
  # A sequence of frames (`frames/3`) shows frames done as well:
  # `frames 6/24, atoms 1536/6144`.

  @enforce_keys [:mode, :total, :t0]
  defstruct [:mode, :total, :t0, done: 0, rays: 0, last_ms: nil, printed_ms: nil, frames: nil]

  @type mode :: :tty | :log | :quiet
  @type t :: %__MODULE__{
          mode: mode(),
          total: pos_integer(),
          t0: integer(),
          done: non_neg_integer(),
          rays: non_neg_integer(),
          last_ms: integer() | nil,
          printed_ms: integer() | nil,
          frames: {non_neg_integer(), pos_integer()} | nil
        }

  @log_every_ms 5_000
  @width 30

  @doc "How often `tick/2` should be called, in ms, for `mode` (`nil`: never)."
  @spec interval(mode()) :: pos_integer() | nil
  def interval(:tty), do: 100
  def interval(:log), do: 1_000
  def interval(:quiet), do: nil

  @doc "A progress display of `mode` for `total` atoms, started at `now_ms`."
  @spec new(mode(), pos_integer(), integer()) :: t()
  def new(mode, total, now_ms), do: %__MODULE__{mode: mode, total: max(total, 1), t0: now_ms}

  @doc "An atom arrived with `rays` rays, at `now_ms`."
  @spec atom(t(), non_neg_integer(), integer()) :: {t(), iodata() | nil}
  def atom(p, rays, now_ms),
    do: {%{p | done: p.done + 1, rays: p.rays + rays, last_ms: now_ms}, nil}

  @doc "Of a sequence: `done` of its `total` frames are done."
  @spec frames(t(), non_neg_integer(), pos_integer()) :: t()
  def frames(p, done, total), do: %{p | frames: {done, total}}

  @doc """
  Time passes: the text to write at `now_ms`, if any.

      iex> p = RingTracer.CLI.Progress.new(:log, 4, 0)
      iex> {p, nil} = RingTracer.CLI.Progress.atom(p, 1_000_000, 1_000)
      iex> {_p, line} = RingTracer.CLI.Progress.tick(p, 5_000)
      iex> IO.iodata_to_binary(line)
      "ringtracer: 1/4 atoms (25%), 0.2 Mrays/s, about 5 s left\\n"
      iex> p = RingTracer.CLI.Progress.frames(p, 1, 3)
      iex> {_p, line} = RingTracer.CLI.Progress.tick(p, 5_000)
      iex> IO.iodata_to_binary(line)
      "ringtracer: frames 1/3, atoms 1/4 (25%), 0.2 Mrays/s, about 5 s left\\n"
  """
  @spec tick(t(), integer()) :: {t(), iodata() | nil}
  def tick(%{mode: :quiet} = p, _now), do: {p, nil}

  def tick(%{mode: :tty} = p, now), do: {%{p | printed_ms: now}, ["\r", bar(p, now), "\e[K"]}

  def tick(%{mode: :log} = p, now) do
    if now - (p.printed_ms || p.t0) >= @log_every_ms and p.done < p.total,
      do: {%{p | printed_ms: now}, [line(p, now), "\n"]},
      else: {p, nil}
  end

  @doc "What to write when the render ends (clears the bar)."
  @spec finish(t()) :: iodata()
  def finish(%{mode: :tty}), do: "\r\e[K"
  def finish(_p), do: []

  # Atoms done, plus what the mean rate says of those in progress: at most
  # just short of one more atom, so the bar never runs ahead of the work.
  defp estimate(%{done: 0}, _now), do: 0.0

  defp estimate(p, now) do
    rate = p.done / max(p.last_ms - p.t0, 1)
    min(p.done + rate * (now - p.last_ms), p.done + 0.95) |> min(p.total / 1)
  end

  defp bar(p, now) do
    est = estimate(p, now)
    filled = min(round(est * @width / p.total), @width)

    [
      "[",
      String.duplicate("#", filled),
      String.duplicate("-", @width - filled),
      "] ",
      count(p),
      "  ",
      rate_text(p, now),
      "  ",
      eta_text(p, now)
    ]
  end

  defp line(p, now) do
    "ringtracer: #{count(p)} (#{div(p.done * 100, p.total)}%), " <>
      "#{rate_text(p, now)}, #{eta_text(p, now)}"
  end

  defp count(%{frames: nil} = p), do: "#{p.done}/#{p.total} atoms"
  defp count(%{frames: {f, n}} = p), do: "frames #{f}/#{n}, atoms #{p.done}/#{p.total}"

  defp rate_text(p, now) do
    mrays = p.rays / max(now - p.t0, 1) / 1000
    "#{:erlang.float_to_binary(mrays, decimals: 1)} Mrays/s"
  end

  defp eta_text(%{done: 0}, _now), do: "starting"

  defp eta_text(p, now) do
    left = (p.total - estimate(p, now)) * (now - p.t0) / max(estimate(p, now), 1.0e-9) / 1000
    "about #{round(left)} s left"
  end
end
