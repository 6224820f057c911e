defmodule RingTracer.CLI.Worker do
  @moduledoc """
  `ringtracer worker`: a distributed node that hosts children of renders
  started on other nodes. Shared by the launcher and `mix ring_tracer.worker`.

  ## Options

    * `--sname NAME` — a short name (on loopback, `NAME@localhost`)
    * `--name NAME@HOST` — a long name
    * `--cookie-file PATH` — the cookie, in a file only you can read
      (default `~/.erlang.cookie`; make one with `ringtracer cookie`)
    * `--listen ADDR` — the address to listen on (default 127.0.0.1: only
      this machine can connect)
    * `--ports MIN-MAX` — the distribution listener's ports, for firewalls
    * `--tls DIR` — distribution over TLS with the certificates in `DIR`
      (`RingTracer.Cluster.TLS`; the launcher boots the VM with TLS).
      Without it, TLS with the user's own certificates
      (`~/.config/ringtracer/tls`, made by `bin/ringtracer` on first use)
    * `--insecure-plain` — plain TCP distribution instead: whoever answers
      on port 4369 (any local user, if she starts epmd first) or sits on
      the network can read and alter the stream
    * `--allow-foreign-epmd` — with `--insecure-plain`, start even when
      epmd belongs to another user
  """

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

  @doc """
  Parses `argv`, makes this node distributed and starts the application.
  Returns the node's name and a line to print, or an error message.
  """
  @spec start([String.t()]) :: {:ok, node(), String.t()} | {:error, String.t()}
  def start(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, [], []} ->
        opts = Paths.expand(opts, [:cookie_file, :tls])

        with {:ok, node} <- Distribution.start(opts),
             {:ok, _} <- Application.ensure_all_started(:ring_tracer) do
          {:ok, node,
           "RingTracer worker #{node} ready (cookie from " <>
             "#{opts[:cookie_file] || "~/.erlang.cookie"}" <>
             "#{transport_note(opts)})"}
        else
          {:error, %RingTracer.Error{message: message}} -> {:error, message}
          {:error, reason} -> {:error, "could not start :ring_tracer: #{inspect(reason)}"}
        end

      {_, extra, []} when extra != [] ->
        {:error, "unexpected argument(s): #{Enum.join(extra, " ")}"}

      {_, _, invalid} ->
        {:error, "invalid option(s): #{Enum.map_join(invalid, ", ", &elem(&1, 0))}"}
    end
  end

  defp transport_note(opts) do
    if opts[:insecure_plain],
      do: ", plain TCP: readable and alterable by whoever answers on port 4369",
      else: ", TLS from #{opts[:tls] || RingTracer.Cluster.TLS.booted_dir()}"
  end
end
