defmodule RingTracer.Options do
  @moduledoc false
  # Validation of `RingTracer.render/2`'s options. Every option is checked
  # before a job starts; a bad one is an `{:error, %RingTracer.Error{reason:
  # :invalid_option}}` that names it. A strategy's own options are its own to
  # check (`RingTracer.Strategy.options/2`, through `RingTracer.Strategies`).

  alias RingTracer.Error

  @schema [
    children: {:pos_integer, nil},
    atoms: {:pos_integer, 16},
    width: {:pos_integer, nil},
    height: {:pos_integer, nil},
    depth: {:pos_integer, RingTracer.Settings.defaults().depth},
    cutoff: {:non_neg_number, RingTracer.Settings.defaults().cutoff},
    samples: {:pos_integer, RingTracer.Settings.defaults().samples},
    frame: {:pos_integer, 1},
    spd: {:boolean, RingTracer.Settings.defaults().spd},
    region: {:region, nil},
    nodes: {:nodes, []},
    timeout: {:timeout, :infinity},
    strategy: {:strategy, :ring},
    kernel: {:kernel, nil},
    layout: {:layout, :strips},
    speeds: {:speeds, []},
    progress: {:pid, nil},
    children_per_node: {:pos_integer, nil},
    local: {:boolean, true},
    allow_dirs: {:paths, []},
    liveness: {:pos_integer, RingTracer.Cluster.Liveness.default_timeout()},
    preview: {:preview, nil},
    pixels: {:pixels, :float},
    ownership: {:boolean, false}
  ]

  # Options that were `render/2`'s and are now the ring's own.
  @ring_options [:hold_after, :aim, :split]

  # Documented maxima, checked before any work. Each is run at full size by
  # `mix ring_tracer.bench limits` (docs/benchmarks.md).
  @max_children 16_384
  @max_atoms 1_048_576

  @doc """
  The default of option `key` (nil when it has none of its own).

      iex> RingTracer.Options.default(:atoms)
      16
  """
  @spec default(atom()) :: term()
  def default(key) do
    {_type, default} = Keyword.fetch!(@schema, key)
    default
  end

  @doc "The largest ring, and the most atoms in all, that a job may have."
  @spec maxima() :: %{children: pos_integer(), atoms: pos_integer()}
  def maxima, do: %{children: @max_children, atoms: @max_atoms}

  @doc """
  Validates `opts` and fills in defaults.

      iex> {:ok, opts} = RingTracer.Options.validate(children: 3)
      iex> {opts[:children], opts[:atoms]}
      {3, 16}
      iex> {:error, %RingTracer.Error{message: message}} = RingTracer.Options.validate(atoms: 0)
      iex> message
      "option :atoms must be a positive integer, got: 0"
      iex> {:error, %RingTracer.Error{message: message}} = RingTracer.Options.validate(split: true)
      iex> message
      "option :split is the ring's own: give it with the strategy, strategy: {:ring, [split: true]}"
  """
  @spec validate(keyword()) :: {:ok, keyword()} | {:error, Error.t()}
  def validate(opts) when is_list(opts) do
    with :ok <- known(opts) do
      Enum.reduce_while(@schema, {:ok, []}, fn {key, {type, default}}, {:ok, acc} ->
        value = Keyword.get(opts, key, default)

        case if(is_nil(value) and is_nil(default), do: :ok, else: check(type, value)) do
          :ok -> {:cont, {:ok, [{key, value} | acc]}}
          {:error, what} -> {:halt, {:error, invalid(key, what, value)}}
        end
      end)
      |> case do
        {:ok, acc} -> finish(Enum.reverse(acc))
        error -> error
      end
    end
  end

  def validate(other),
    do:
      {:error,
       Error.new(:invalid_option, "options must be a keyword list, got: #{inspect(other)}")}

  defp finish(opts) do
    opts = place(opts)

    cond do
      opts[:children] > @max_children ->
        {:error, invalid(:children, "at most #{@max_children}", opts[:children])}

      opts[:children] * opts[:atoms] > @max_atoms ->
        {:error,
         Error.new(
           :invalid_option,
           "options :children x :atoms must be at most #{@max_atoms} atoms in all, " <>
             "got: #{opts[:children]} x #{opts[:atoms]} = #{opts[:children] * opts[:atoms]}"
         )}

      true ->
        early_strategy(opts)
    end
  end

  # The strategy's own options (`RingTracer.Strategy.options/2`), checked
  # before any work on a layout of the job's shape, of one frame and of one
  # row per atom (its image is not known yet): the job checks them again on
  # its own layout, which only a sequence's frames change.
  defp early_strategy(opts) do
    n = opts[:children]
    k = opts[:atoms]
    layout = RingTracer.Layout.new(n * k, 1, n, k, opts[:layout])

    with {:ok, _} <- RingTracer.Strategies.resolve(opts[:strategy], layout), do: {:ok, opts}
  end

  # Nodes: the local node first unless `local: false`, then the others; with
  # `:children_per_node` the ring has that many children on each, in a row,
  # otherwise `:children` are dealt round robin. `:nodes` becomes one node
  # per child.
  defp place(opts) do
    nodes =
      case opts[:nodes] do
        [] -> []
        others -> Enum.uniq(if(opts[:local], do: [node()], else: []) ++ others)
      end

    cond do
      nodes == [] ->
        Keyword.update!(opts, :children, &(&1 || System.schedulers_online()))

      cpn = opts[:children_per_node] ->
        placement = for n <- nodes, _ <- 1..cpn, do: n
        Keyword.merge(opts, children: length(placement), nodes: placement)

      true ->
        n = opts[:children] || System.schedulers_online() * length(nodes)

        Keyword.merge(opts,
          children: n,
          nodes: for(i <- 0..(n - 1), do: Enum.at(nodes, rem(i, length(nodes))))
        )
    end
  end

  defp known(opts) do
    case Keyword.keys(opts) -- Keyword.keys(@schema) do
      [] ->
        :ok

      [key | _] when key in @ring_options ->
        {:error,
         Error.new(
           :invalid_option,
           "option #{inspect(key)} is the ring's own: give it with the strategy, " <>
             "strategy: {:ring, [#{key}: #{inspect(opts[key])}]}"
         )}

      [key | _] ->
        {:error,
         Error.new(
           :invalid_option,
           "unknown option #{inspect(key)}; known: #{inspect(Keyword.keys(@schema))}"
         )}
    end
  end

  defp check(:pos_integer, v) when is_integer(v) and v > 0, do: :ok
  defp check(:pos_integer, _), do: {:error, "a positive integer"}
  defp check(:non_neg_integer, v) when is_integer(v) and v >= 0, do: :ok
  defp check(:non_neg_integer, _), do: {:error, "a non-negative integer"}
  defp check(:non_neg_number, v) when is_number(v) and v >= 0, do: :ok
  defp check(:non_neg_number, _), do: {:error, "a non-negative number"}
  defp check(:boolean, v) when is_boolean(v), do: :ok
  defp check(:boolean, _), do: {:error, "a boolean"}
  defp check(:timeout, :infinity), do: :ok
  defp check(:timeout, v) when is_integer(v) and v > 0, do: :ok
  defp check(:timeout, _), do: {:error, "a positive integer (ms) or :infinity"}

  defp check(:region, nil), do: :ok

  defp check(:region, {x0, y0, x1, y1} = r) do
    ints? = Enum.all?([x0, y0, x1, y1], &(is_integer(&1) and &1 >= 0))
    fracs? = Enum.all?([x0, y0, x1, y1], &(is_float(&1) and &1 >= 0 and &1 <= 1))

    if (ints? or fracs?) and x0 < x1 and y0 < y1,
      do: :ok,
      else: check(:region, {:bad, r})
  end

  defp check(:region, _),
    do:
      {:error,
       "{x0, y0, x1, y1}: pixels (integers, x1 and y1 excluded) or fractions of the " <>
         "image (floats from 0.0 to 1.0), with x0 < x1 and y0 < y1"}

  defp check(:nodes, v) when is_list(v) do
    if Enum.all?(v, &is_atom/1), do: :ok, else: {:error, "a list of node names (atoms)"}
  end

  defp check(:nodes, _), do: {:error, "a list of node names (atoms)"}

  defp check(:strategy, v), do: RingTracer.Strategies.check(v)

  defp check(:kernel, {m, o}) when is_atom(m) and is_list(o), do: :ok
  defp check(:kernel, _), do: {:error, "a kernel as {module, options} (see RingTracer.Kernel)"}

  defp check(:layout, v) do
    if v in RingTracer.Layout.orders(),
      do: :ok,
      else: {:error, "one of #{inspect(RingTracer.Layout.orders())}"}
  end

  defp check(:speeds, v) when is_list(v) do
    if Enum.all?(v, &RingTracer.Job.Slowdown.factor?/1),
      do: :ok,
      else: {:error, "a list of slowdown factors from 1 to #{RingTracer.Job.Slowdown.max()}"}
  end

  defp check(:speeds, _),
    do: {:error, "a list of slowdown factors from 1 to #{RingTracer.Job.Slowdown.max()}"}

  defp check(:paths, v) when is_list(v) do
    if Enum.all?(v, &is_binary/1), do: :ok, else: {:error, "a list of folder paths (strings)"}
  end

  defp check(:paths, _), do: {:error, "a list of folder paths (strings)"}
  defp check(:preview, v) when is_boolean(v) or is_struct(v, RingTracer.Preview), do: :ok
  defp check(:preview, v) when is_integer(v) and v in 0..65_535, do: :ok

  defp check(:preview, v) when is_list(v) do
    ok? =
      Keyword.keyword?(v) and
        Enum.all?(v, fn
          {:port, p} -> is_integer(p) and p in 0..65_535
          {:listen, a} -> match?({:ok, _}, RingTracer.Preview.address(a))
          {:max_viewers, m} -> is_integer(m) and m > 0
          {:cpu_share, c} -> is_number(c) and c > 0 and c <= 1
          {:strip, n} -> is_integer(n) and n > 0
          {:announce, d} -> is_pid(d) or is_atom(d)
          _ -> false
        end)

    if ok?, do: :ok, else: check(:preview, :bad)
  end

  defp check(:preview, _),
    do:
      {:error,
       "true, a port (0 for a free one), [port: p, listen: address, max_viewers: n, " <>
         "cpu_share: 0.01, strip: 12] " <>
         "or a RingTracer.Preview"}

  defp check(:pixels, v) do
    if v in RingTracer.Pixels.formats(),
      do: :ok,
      else:
        {:error,
         "one of #{inspect(RingTracer.Pixels.formats())} (:srgb8 only when every " <>
           "image written is 8-bit, e.g. PNG)"}
  end

  defp check(:pid, v) when is_pid(v), do: :ok
  defp check(:pid, _), do: {:error, "a pid"}

  defp invalid(key, what, value),
    do:
      Error.new(:invalid_option, "option #{inspect(key)} must be #{what}, got: #{inspect(value)}")
end
