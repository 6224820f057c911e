defmodule RingTracer.Cluster.Build do
  @moduledoc false
  # Which build of RingTracer a node runs, so that nodes of different builds
  # never work together.
  #
  # A build is the application's version, a hash of its compiled code (the
  # MD5 of each module of `:ring_tracer`, as `module_info(:md5)` gives it,
  # sorted by module and hashed together) and a SHA-256 of the NIF's shared
  # library as it is on disk at the application's start, right after the NIF
  # was loaded. Two nodes of the same version built from different sources,
  # or with a different kernel, have different builds.
  #
  # The identity is computed once per node (a few tens of milliseconds), by
  # `RingTracer.Cluster` right after the application's start (or by the first
  # call that needs it sooner), and kept in `:persistent_term`; `identity/0`
  # reads it from there. A node whose application has not started yet tells
  # no build: `check/2` treats it as one that cannot be reached.
  #
  # Every place where nodes meet before work compares builds: a node asked
  # to host a job's children (at the start and when the ring grows,
  # `RingTracer.Job.Host`), `RingTracer.Cluster.check/1`, a farm worker
  # joining its head and a submitter queueing a job. A mismatch is
  # refused with an error of reason `:build_mismatch` that names both builds:
  #
  #     node w1@host runs build 0.1.0+3f2a9c1d, node head@host runs build 0.1.0+77e0b1a4
  #     (the code differs); every node of a cluster must run the same build: ...

  alias RingTracer.Error

  @enforce_keys [:version, :code, :nif]
  defstruct [:version, :code, :nif]

  @typedoc """
  A build: `version` the application's, `code` the hash of its modules,
  `nif` the hash of its NIF's library (`nil` when there is none to read).
  """
  @type t :: %__MODULE__{version: String.t(), code: binary(), nif: binary() | nil}

  @key {__MODULE__, :identity}
  @nif_key {__MODULE__, :nif}
  @call_ms 5_000

  @doc """
  This node's build, computed on the first call and kept for the next.

      iex> RingTracer.Cluster.Build.identity() == RingTracer.Cluster.Build.identity()
      true
  """
  @spec identity() :: t()
  def identity do
    case :persistent_term.get(@key, nil) do
      %__MODULE__{} = build ->
        build

      nil ->
        build = compute()
        # Kept once the application is loaded (before, it has no version).
        if build.version != "unknown", do: :persistent_term.put(@key, build)
        build
    end
  end

  @doc false
  # What check/2 asks another node: its build, once its application runs
  # (a node still starting, a head that restarts, is not there yet).
  @spec running_identity() :: {:ok, t()} | :not_running
  def running_identity do
    if Process.whereis(RingTracer.Supervisor) != nil,
      do: {:ok, identity()},
      else: :not_running
  end

  @doc false
  # At the application's start: the NIF's library, hashed while it is the
  # one just loaded.
  @spec init() :: :ok
  def init, do: :persistent_term.put(@nif_key, nif_hash())

  @doc false
  # Where identity/0 keeps the build (tests put another one there to make a
  # node pretend to be of another build).
  @spec key() :: term()
  def key, do: @key

  @doc """
  The build of the code loaded now, computed afresh (`identity/0` keeps the
  first one); the NIF's hash is the one taken at the application's start.
  """
  @spec compute() :: t()
  def compute do
    nif =
      case :persistent_term.get(@nif_key, :none) do
        :none -> nif_hash()
        hash -> hash
      end

    %__MODULE__{version: version(), code: code_hash(), nif: nif}
  end

  @doc """
  A build's short printable form: its version, `+`, and the first 8 hex
  digits of the hash of its code and NIF together (`0.1.0+3f2a9c1d`).
  Anything that is not a build (a node too old to tell its build) prints
  as `an unknown build`.
  """
  @spec short(t() | term()) :: String.t()
  def short(%__MODULE__{version: v, code: code, nif: nif})
      when is_binary(v) and is_binary(code) do
    hash = :erlang.md5([code, nif || ""]) |> Base.encode16(case: :lower) |> binary_part(0, 8)
    "#{v}+#{hash}"
  end

  def short(_), do: "an unknown build"

  @doc """
  Compares the build `theirs` of `node` with this node's: `:ok` when they
  are the same, else an error of reason `:build_mismatch` naming both and
  what differs.
  """
  @spec compare(node(), t() | term()) :: :ok | {:error, Error.t()}
  def compare(node, theirs), do: compare(node, theirs, identity())

  @doc """
  Compares the build `theirs` of `node` with `ours`, this node's.

      iex> alias RingTracer.Cluster.Build
      iex> a = %Build{version: "0.1.0", code: "a", nif: "n"}
      iex> Build.compare(:w1@host, a, a)
      :ok
      iex> {:error, e} = Build.compare(:w1@host, %{a | code: "b"}, a)
      iex> e.reason
      :build_mismatch
      iex> e.message =~ "node w1@host runs build 0.1.0+"
      true
  """
  @spec compare(node(), t() | term(), t()) :: :ok | {:error, Error.t()}
  def compare(_node, same, same), do: :ok

  def compare(node, theirs, ours) do
    {:error,
     Error.new(
       :build_mismatch,
       "node #{node} runs #{named(theirs)}, node #{node()} runs #{named(ours)} " <>
         "(#{difference(theirs, ours)}); every node of a cluster must run the same build: " <>
         "install the same release (or build the same checkout) on both"
     )}
  end

  defp named(%__MODULE__{} = build), do: "build " <> short(build)
  defp named(other), do: short(other)

  defp difference(%__MODULE__{version: v1} = a, %__MODULE__{version: v2} = b) do
    cond do
      v1 != v2 -> "the versions differ"
      a.code != b.code -> "the code differs"
      true -> "the NIF differs"
    end
  end

  defp difference(_, _), do: "it does not tell its build: a RingTracer from before build checks"

  @doc """
  Asks `node` for its build and compares it with this node's. `:ok` for
  this node itself. An error of reason `:build_mismatch` when the builds
  differ, `{:error, {:call, reason}}` when the call failed (what `:erpc`
  raised: `{:erpc, :noconnection}`, ...; `:not_running` for a node whose
  application has not started), for the caller to word.

  ## Options

    * `:timeout` — how long to wait for `node`, in ms (default #{@call_ms})
  """
  @spec check(node(), keyword()) :: :ok | {:error, Error.t() | {:call, term()}}
  def check(node, opts \\ [])
  def check(node, _opts) when node == node(), do: :ok

  def check(node, opts) do
    case :erpc.call(node, __MODULE__, :running_identity, [], opts[:timeout] || @call_ms) do
      {:ok, theirs} -> compare(node, theirs)
      :not_running -> {:error, {:call, :not_running}}
    end
  rescue
    e in ErlangError ->
      case e.original do
        # the node has no such function: a RingTracer from before builds
        {:exception, :undef, _} -> compare(node, :unknown)
        original -> {:error, {:call, original}}
      end
  end

  defp version do
    case Application.spec(:ring_tracer, :vsn) do
      nil -> "unknown"
      vsn -> List.to_string(vsn)
    end
  end

  defp code_hash do
    modules = Application.spec(:ring_tracer, :modules) || []
    ebin = ebin()

    modules
    |> Enum.sort()
    |> Enum.map(&[Atom.to_string(&1), module_md5(&1, ebin)])
    |> :erlang.md5()
  end

  defp ebin do
    case :code.lib_dir(:ring_tracer) do
      {:error, _} -> nil
      dir -> Path.join(to_string(dir), "ebin")
    end
  end

  # A loaded module's MD5 is the one of the code running; beam_lib's for
  # one not loaded yet is the same value, read from its file in the
  # application's folder (not through the code path, which a node with a
  # long one searches slowly).
  defp module_md5(module, ebin) do
    with false <- :code.is_loaded(module),
         true <- ebin != nil,
         path = String.to_charlist(Path.join(ebin, Atom.to_string(module) <> ".beam")),
         {:ok, {_, md5}} <- :beam_lib.md5(path) do
      md5
    else
      {:file, _} -> module.module_info(:md5)
      _ -> "missing"
    end
  end

  defp nif_hash do
    case :code.priv_dir(:ring_tracer) do
      {:error, _} ->
        nil

      priv ->
        case File.read(Path.join([to_string(priv), "native", "libring_tracer_nif.so"])) do
          {:ok, bytes} -> :crypto.hash(:sha256, bytes)
          {:error, _} -> nil
        end
    end
  end
end
