defmodule RingTracer.Report.Stats do
  @moduledoc false
  # Numbers about a render (`RingTracer.Result`), as a map, JSON or CSV.
  #
  # `summary/1` gives the makespan and the ideal makespan, their ratio, the
  # idle share, messages and bytes by kind and per atom, the per-child stats,
  # image size, atom count and ray counters. `write/2` writes the summary as
  # JSON (`.json`) or the per-child table as CSV (`.csv`).

  alias RingTracer.{Error, Result}

  # A child's statistics, one column each (`RingTracer.Job.Stats`).
  @child_columns RingTracer.Job.Stats.columns()

  @doc """
  A summary of `result`:

    * `:strategy`, `:strategy_options` (a map), `:layout`, `:width`, `:height`, `:atoms` (count), `:children_count`;
    * `:started_at_us` (wall clock, when the job started), `:first_atom_us`
      (when the first atom's pixels were ready, from the start);
    * `:makespan_us`, `:ideal_us`, `:ratio` (makespan / ideal, `nil` when the
      ideal is 0), `:idle_pct` (the children's summed idle time as a
      percentage of `children * makespan`);
    * `:messages` — `%{kind => %{count: n, bytes: b}}` as in the result,
      `:messages_total` — `%{count: n, bytes: b}`, `:per_atom` —
      `%{messages: x, bytes: y, by_kind: %{kind => %{count: x, bytes: y}}}`;
    * `:children` — the per-child maps, `:node` as a string;
    * `:rays` — the ray counters; `:duplicates`.
  """
  @spec summary(Result.t()) :: map()
  def summary(%Result{} = result) do
    children = result.children || []
    atoms = length(result.atoms || [])
    messages = result.messages || %{}
    n = length(children)
    makespan = result.elapsed_us || 0
    ideal = result.ideal_us || 0
    idle = Enum.reduce(children, 0, &((Map.get(&1, :idle_us) || 0) + &2))
    per = max(atoms, 1)

    {count, bytes} =
      Enum.reduce(messages, {0, 0}, fn {_, m}, {c, b} -> {c + m.count, b + m.bytes} end)

    %{
      strategy: result.strategy,
      layout: result.layout,
      strategy_options: Map.new(result.strategy_options || []),
      width: result.width,
      height: result.height,
      atoms: atoms,
      children_count: n,
      started_at_us: result.started_at_us,
      first_atom_us:
        result.atoms |> List.wrap() |> Enum.map(& &1.end_us) |> Enum.min(fn -> nil end),
      makespan_us: makespan,
      ideal_us: ideal,
      ratio: if(ideal > 0, do: makespan / ideal, else: nil),
      idle_pct: if(n > 0 and makespan > 0, do: 100 * idle / (n * makespan), else: 0.0),
      messages: messages,
      messages_total: %{count: count, bytes: bytes},
      per_atom: %{
        messages: count / per,
        bytes: bytes / per,
        by_kind:
          Map.new(messages, fn {k, m} -> {k, %{count: m.count / per, bytes: m.bytes / per}} end)
      },
      children: Enum.map(children, &child/1),
      rays: result.rays,
      duplicates: result.duplicates
    }
  end

  # A child's statistics as a plain map, its node as a string.
  defp child(stats) do
    stats
    |> Map.delete(:__struct__)
    |> Map.update(:node, nil, &to_string/1)
  end

  @doc """
  Writes the summary of `result` to `path`: `.json` writes `summary/1` as
  pretty-printed JSON, `.csv` one row per child under a header (ray counters
  as `rays_<kind>` columns).

  Returns `{:error, %RingTracer.Error{reason: :file}}` for any other
  extension or when the file cannot be written. Options as
  `RingTracer.Output.write/3`'s.
  """
  @spec write(Result.t(), Path.t(), keyword()) :: :ok | {:error, Error.t()}
  def write(%Result{} = result, path, opts \\ []) when is_binary(path) do
    case String.downcase(Path.extname(path)) do
      ".json" ->
        with {:ok, json} <- encode_json(summary(result), path),
             do: RingTracer.Output.write(path, [json, "\n"], opts)

      ".csv" ->
        RingTracer.Output.write(path, csv(result), opts)

      ext ->
        {:error,
         Error.new(:file, "#{path}: unknown stats format #{inspect(ext)}; use .json or .csv")}
    end
  end

  @doc """
  The per-child CSV of `result` (header and one line per child) as iodata.
  """
  @spec csv(Result.t()) :: iodata()
  def csv(%Result{children: children}) do
    children = children || []

    ray_keys = children |> Enum.flat_map(&Map.keys(rays(&1))) |> Enum.uniq() |> Enum.sort()

    header = Enum.map(@child_columns, &Atom.to_string/1) ++ Enum.map(ray_keys, &"rays_#{&1}")

    rows =
      Enum.map(children, fn child ->
        Enum.map(@child_columns, &Map.get(child, &1)) ++ Enum.map(ray_keys, &rays(child)[&1])
      end)

    Enum.map([header | rows], fn row -> [Enum.map_join(row, ",", &field/1), "\n"] end)
  end

  defp rays(child), do: Map.get(child, :rays) || %{}

  defp field(nil), do: ""
  defp field(x) when is_float(x), do: :erlang.float_to_binary(x, [:compact, decimals: 6])
  defp field(x) when is_integer(x), do: Integer.to_string(x)

  defp field(x) do
    s = to_string(x)

    if String.contains?(s, [",", "\"", "\n", "\r"]),
      do: ~s("#{String.replace(s, "\"", "\"\"")}"),
      else: s
  end

  # jiffy is Debian's erlang-jiffy (an application listed in mix.exs, not a
  # hex dependency); bin/ringtracer installs it.
  defp encode_json(term, path) do
    if Code.ensure_loaded?(:jiffy) do
      {:ok, :jiffy.encode(json(term), [:pretty])}
    else
      {:error,
       Error.new(:file, "#{path}: cannot write JSON, Debian's erlang-jiffy is not installed")}
    end
  end

  # Terms jiffy encodes: binary keys, no tuples, nil as null.
  defp json(nil), do: :null
  defp json(b) when is_boolean(b), do: b
  defp json(a) when is_atom(a), do: Atom.to_string(a)
  defp json(x) when is_number(x) or is_binary(x), do: x
  defp json(%{} = map), do: Map.new(map, fn {k, v} -> {key(k), json(v)} end)
  defp json(list) when is_list(list), do: Enum.map(list, &json/1)
  defp json(tuple) when is_tuple(tuple), do: tuple |> Tuple.to_list() |> json()
  defp json(other), do: inspect(other)

  defp key(k) when is_binary(k), do: k
  defp key(k) when is_atom(k) or is_number(k), do: to_string(k)
  defp key(k), do: inspect(k)
end
