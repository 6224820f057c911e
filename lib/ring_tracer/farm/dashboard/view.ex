defmodule RingTracer.Farm.Dashboard.View do
  @moduledoc false
  # What the dashboard's page shows, made from `RingTracer.Farm.overview/2`
  # (pure), and its JSON (`state.json`):
  #
  #   * `head` — the head's node, `now` — the head's clock (ms since the epoch)
  #   * `workers` — per worker: `node`, `state` (`"idle"` or `"working"`),
  #     `job` (its id, or null), `speed`, `slots`, `tags`, `joined_at`
  #   * `jobs` — the jobs not ended, in submission order, then the last
  #     #{20} ended (`ended_omitted` counts the others): `id`, `user`,
  #     `scene`, `state`, `priority`, `tags`, `width`, `height`, `frames`
  #     (how many), `done` (how many), `progress` (0 to 1), `time_left`
  #     (ms, or null), `preview` (the running job's page, or null), `workers`,
  #     `error`, `submitted_at`, `started_at`, `finished_at`
  #   * `queue` — the ids of the jobs waiting for workers, higher priority
  #     first, then in submission order
  #
  # Strings from jobs (users, scene names, errors) are attacker-controlled:
  # the page only ever sets them as text, and the JSON has every `<`, `>` and
  # `&` escaped (`\\u003c`...), so even a browser that sniffed it as HTML
  # would find no markup in it.

  alias RingTracer.Farm.{JobInfo, WorkerInfo}

  @ended_shown 20

  @enforce_keys [:head, :now]
  defstruct [:head, :now, workers: [], jobs: [], queue: [], ended_omitted: 0]

  @type t :: %__MODULE__{
          head: node(),
          now: integer(),
          workers: [map()],
          jobs: [map()],
          queue: [pos_integer()],
          ended_omitted: non_neg_integer()
        }

  @doc "The view of a farm's overview on `head` at `now` (ms since the epoch)."
  @spec new(
          %{
            :workers => [WorkerInfo.t()],
            :jobs => [JobInfo.t()],
            optional(atom()) => term()
          },
          node(),
          integer()
        ) :: t()
  def new(%{workers: workers, jobs: jobs}, head, now) do
    {ended, live} = Enum.split_with(jobs, &RingTracer.Farm.Job.ended_state?(&1.state))
    shown = Enum.take(ended, -@ended_shown)

    queue =
      live
      |> Enum.filter(&(&1.state == :queued))
      |> Enum.sort_by(&{-&1.priority, &1.id})
      |> Enum.map(& &1.id)

    %__MODULE__{
      head: head,
      now: now,
      workers: Enum.map(workers, &worker/1),
      jobs: Enum.map(live ++ shown, &job/1),
      queue: queue,
      ended_omitted: length(ended) - length(shown)
    }
  end

  defp worker(%WorkerInfo{} = w) do
    %{
      node: Atom.to_string(w.node),
      state: if(w.job, do: "working", else: "idle"),
      job: w.job,
      speed: w.speed,
      slots: w.slots,
      tags: Enum.map(w.tags, &text/1),
      joined_at: w.joined_at
    }
  end

  defp job(%JobInfo{} = j) do
    %{
      id: j.id,
      user: text(j.user),
      scene: text(j.scene),
      state: Atom.to_string(j.state),
      priority: j.priority,
      tags: Enum.map(j.tags, &text/1),
      width: j.width,
      height: j.height,
      frames: length(j.frames),
      done: length(j.done),
      progress: j.progress,
      time_left: j.time_left,
      preview: j.preview,
      workers: Enum.map(j.workers, &Atom.to_string/1),
      error: text(j.error),
      submitted_at: j.submitted_at,
      started_at: j.started_at,
      finished_at: j.finished_at
    }
  end

  # A string as valid UTF-8: each byte that is not becomes U+FFFD.
  defp text(nil), do: nil

  defp text(bytes) do
    case :unicode.characters_to_binary(bytes) do
      good when is_binary(good) -> good
      {_, good, <<_, rest::binary>>} -> good <> "\uFFFD" <> text(rest)
    end
  end

  @doc """
  The view as JSON text; `<`, `>` and `&` only ever appear escaped.

      iex> view = %RingTracer.Farm.Dashboard.View{head: :h@x, now: 0}
      iex> RingTracer.Farm.Dashboard.View.encode(view) =~ ~s("head":"h@x")
      true
  """
  @spec encode(t()) :: binary()
  def encode(%__MODULE__{} = view) do
    view
    |> Map.from_struct()
    |> Map.update!(:head, &Atom.to_string/1)
    |> :jiffy.encode([:use_nil])
    |> IO.iodata_to_binary()
    # Outside strings, JSON has none of these characters.
    |> String.replace(["<", ">", "&"], fn
      "<" -> "\\u003c"
      ">" -> "\\u003e"
      "&" -> "\\u0026"
    end)
  end
end
