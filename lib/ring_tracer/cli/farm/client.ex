defmodule RingTracer.CLI.Farm.Client do
  @moduledoc false
  # What every command that talks to a farm's head shares (`submit`, `jobs`,
  # `status`, `wait`, `cancel`, `fetch`): the head's name from `--farm HEAD`
  # (or `RINGTRACER_FARM`), and this node made a distributed client of it with
  # the farm's credentials: the cookie from a file (`--cookie-file`, default
  # `~/.erlang.cookie`) and the TLS folder the launcher booted the VM with
  # (`--tls DIR`, default the user's own), never a secret on the command line.
  #
  # ## Options
  #
  #   * `--farm HEAD` — the head's node name (`farm@localhost`); a name
  #     without `@` is on `localhost`. Default: `$RINGTRACER_FARM`
  #   * the distribution switches of `RingTracer.CLI.Worker.switches/0`; this
  #     node gets a made-up name unless `--sname` or `--name` gives one (a
  #     long one when the head's name is long)

  alias RingTracer.CLI.Paths
  alias RingTracer.Cluster.Distribution

  @switches [farm: :string] ++ RingTracer.CLI.Worker.switches()
  @distribution Keyword.keys(RingTracer.CLI.Worker.switches())

  @doc "The switches of a farm client: `--farm` and the distribution ones."
  @spec switches() :: keyword()
  def switches, do: @switches

  @doc "Every switch `switches/0` holds but `--farm`: those that set up distribution."
  @spec distribution_keys() :: [atom()]
  def distribution_keys, do: @distribution

  @doc """
  The head's node name from `opts` (`:farm`) or `RINGTRACER_FARM`.

      iex> RingTracer.CLI.Farm.Client.head([farm: "farm@localhost"])
      {:ok, :"farm@localhost"}
      iex> RingTracer.CLI.Farm.Client.head([farm: "farm"])
      {:ok, :"farm@localhost"}
      iex> RingTracer.CLI.Farm.Client.head([farm: "a b@c"])
      {:usage, "--farm takes the head's node name, NAME@HOST (as `ringtracer farm` prints it), got: a b@c"}
  """
  @spec head(keyword()) :: {:ok, node()} | {:usage, String.t()}
  def head(opts) do
    case opts[:farm] || System.get_env("RINGTRACER_FARM") do
      nil ->
        {:usage,
         "--farm HEAD is required: the head's node name, as `ringtracer farm` prints it " <>
           "(or set RINGTRACER_FARM)"}

      text ->
        name = if String.contains?(text, "@"), do: text, else: text <> "@localhost"

        if name =~ ~r/\A[A-Za-z0-9_-]{1,200}@[A-Za-z0-9.:-]{1,255}\z/,
          do: {:ok, String.to_atom(name)},
          else:
            {:usage,
             "--farm takes the head's node name, NAME@HOST (as `ringtracer farm` prints it), " <>
               "got: #{text}"}
    end
  end

  @doc """
  Makes this node a distributed client (unless it is one already), starts
  the application and connects to `head`. A head that cannot be reached
  is an error naming it and the usual causes.
  """
  @spec connect(keyword(), node()) :: :ok | {:error, String.t()}
  def connect(opts, head) do
    opts = Paths.expand(opts, [:cookie_file, :tls])
    dist = Keyword.take(opts, @distribution)

    with :ok <- distribution(dist, head),
         :ok <- application() do
      if Node.connect(head) == true,
        do: :ok,
        else: {:error, unreachable(head)}
    end
  end

  @doc "The message for a head that cannot be reached."
  @spec unreachable(node()) :: String.t()
  def unreachable(head) do
    "cannot reach the farm head #{head}: is `ringtracer farm` running there, and do both " <>
      "nodes use the same cookie file and TLS certificates (one CA)?"
  end

  defp distribution(dist, head) do
    dist =
      if long?(head) and not Keyword.has_key?(dist, :name) and not Keyword.has_key?(dist, :sname),
        do: Keyword.put(dist, :name, "#{Distribution.unique_name("ringtracer")}@#{host(dist)}"),
        else: dist

    case Distribution.start(dist ++ [generate: true]) do
      {:ok, _} -> :ok
      {:error, %RingTracer.Error{message: message}} -> {:error, message}
    end
  end

  # A head named NAME@HOST.DOMAIN or NAME@ADDRESS runs long names: so must we.
  defp long?(head) do
    [_, host] = head |> Atom.to_string() |> String.split("@", parts: 2)
    String.contains?(host, ".") or String.contains?(host, ":")
  end

  defp host(dist), do: dist[:listen] || "127.0.0.1"

  defp application do
    case Application.ensure_all_started(:ring_tracer) do
      {:ok, _} -> :ok
      {:error, reason} -> {:error, "could not start :ring_tracer: #{inspect(reason)}"}
    end
  end
end
