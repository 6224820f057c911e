defmodule RingTracer.CLI.Worker do
  @moduledoc false
  # `ringtracer worker`: a distributed node that hosts children of renders
  # started on other nodes, or, with `--join HEAD`, a farm's worker. Shared
  # by the launcher and `mix ring_tracer.worker`.
  #
  # ## Options
  #
  #   * `--sname NAME` — a short name (on loopback, `NAME@localhost`)
  #   * `--name NAME@HOST` — a long name
  #   * `--cookie-file PATH` — the cookie, in a file only you can read
  #     (default `~/.erlang.cookie`; make one with `ringtracer cookie`)
  #   * `--listen ADDR` — the address to listen on (default 127.0.0.1: only
  #     this machine can connect)
  #   * `--ports MIN-MAX` — the distribution listener's ports, for firewalls
  #   * `--tls DIR` — distribution over TLS with the certificates in `DIR`
  #     (`RingTracer.Cluster.TLS`; the launcher boots the VM with TLS).
  #     Without it, TLS with the user's own certificates
  #     (`~/.config/ringtracer/tls`, made by `bin/ringtracer` on first use)
  #   * `--insecure-plain` — plain TCP distribution instead: whoever answers
  #     on port 4369 (any local user, if she starts epmd first) or sits on
  #     the network can read and alter the stream
  #   * `--allow-foreign-epmd` — with `--insecure-plain`, start even when
  #     epmd belongs to another user
  #   * `--join HEAD` — joins the farm whose head is `HEAD`
  #     (`RingTracer.Farm.join/2`), now or as soon as it can be reached, and
  #     again whenever the head restarts; the node may then go unnamed (a
  #     name is made up)
  #   * `--tags a,b`, `--slots N`, `--speed F` — with `--join`: tags a job may
  #     ask for, the children this worker hosts for a job (default: one per
  #     core), and a slowdown that emulates a slower machine (1 to
  #     `RingTracer.Job.Slowdown.max/0`)

  alias RingTracer.CLI.Paths
  alias RingTracer.Cluster.Distribution

  @switches [
    sname: :string,
    name: :string,
    cookie: :string,
    cookie_file: :string,
    listen: :string,
    ports: :string,
    tls: :string,
    insecure_plain: :boolean,
    allow_foreign_epmd: :boolean
  ]

  @doc "The command-line switches that make a node distributed (also the render's)."
  @spec switches() :: [{atom(), :string | :boolean}]
  def switches, do: @switches

  @join_switches [join: :string, tags: :string, slots: :integer, speed: :float]

  @doc """
  Parses `argv`, makes this node distributed and starts the application;
  with `--join HEAD`, makes it a worker of that farm
  (`RingTracer.Farm.join/2`), which joins again by itself whenever the
  head restarts. Returns the node's name and a line to print, or an error
  message.
  """
  @spec start([String.t()]) :: {:ok, node(), String.t()} | {:error, String.t()}
  def start(argv) do
    case OptionParser.parse(argv, strict: @switches ++ @join_switches) do
      {opts, [], []} ->
        opts = Paths.expand(opts, [:cookie_file, :tls])
        {join, opts} = Keyword.split(opts, Keyword.keys(@join_switches))
        # a farm's worker may go unnamed: the head knows it by what it makes up
        opts =
          if join[:join] && !opts[:sname] && !opts[:name],
            do: opts ++ [sname: Distribution.unique_name("worker")],
            else: opts

        with {:ok, member} <- membership(join),
             {:ok, node} <- distribute(opts),
             {:ok, line} <- join(member, join) do
          {:ok, node, "RingTracer worker #{node} ready (#{credentials(opts)})" <> line}
        end

      {_, extra, []} when extra != [] ->
        {:error, "unexpected argument(s): #{Enum.join(extra, " ")}"}

      {_, _, invalid} ->
        {:error, "invalid option(s): #{Enum.map_join(invalid, ", ", &elem(&1, 0))}"}
    end
  end

  @doc """
  Makes this node distributed as `opts` (parsed switches, paths expanded)
  say and starts the application. Returns the node's name or an error
  message.
  """
  @spec distribute(keyword()) :: {:ok, node()} | {:error, String.t()}
  def distribute(opts) do
    with {:ok, node} <- Distribution.start(opts),
         {:ok, _} <- Application.ensure_all_started(:ring_tracer) do
      {:ok, node}
    else
      {:error, %RingTracer.Error{message: message}} -> {:error, message}
      {:error, reason} -> {:error, "could not start :ring_tracer: #{inspect(reason)}"}
    end
  end

  @doc "Where a node's credentials come from, in words (nothing secret)."
  @spec credentials(keyword()) :: String.t()
  def credentials(opts) do
    "cookie from #{opts[:cookie_file] || "~/.erlang.cookie"}#{transport_note(opts)}"
  end

  # --join HEAD and what the worker offers, checked before the node starts.
  defp membership(join) do
    cond do
      join[:join] == nil and join != [] ->
        {:error, "--tags, --slots and --speed are a farm worker's: give --join HEAD with them"}

      join[:join] == nil ->
        {:ok, nil}

      true ->
        case RingTracer.CLI.Farm.Client.head(farm: join[:join]) do
          {:ok, head} -> {:ok, head}
          {:usage, message} -> {:error, String.replace(message, "--farm", "--join")}
        end
    end
  end

  defp join(nil, _join), do: {:ok, ""}

  defp join(head, join) do
    tags =
      case join[:tags] do
        nil -> []
        text -> text |> String.split(",", trim: true) |> Enum.map(&String.trim/1)
      end

    opts = [tags: tags] ++ Keyword.take(join, [:slots, :speed])

    case RingTracer.Farm.join(head, opts) do
      {:ok, _} ->
        {:ok, "; joining the farm #{head} (again by itself whenever its head restarts)"}

      {:error, %RingTracer.Error{message: message}} ->
        {:error, RingTracer.CLI.Render.cli_names(message)}
    end
  end

  defp transport_note(opts) do
    if opts[:insecure_plain],
      do: ", plain TCP: readable and alterable by whoever answers on port 4369",
      else: ", TLS from #{opts[:tls] || RingTracer.Cluster.TLS.booted_dir()}"
  end
end
