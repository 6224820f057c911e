defmodule RingTracer.Preview do
  @moduledoc """
  A live page of a running render, in a browser: the image filling in atom
  by atom, who traced what, one lane per child growing as it works with its
  help offers and hand-overs, and the job's counters; at the end, its final
  statistics. For a sequence (`RingTracer.render_sequence/2`, same
  `:preview` option), the oldest frame in flight fills in (at the end, the
  last frame), with the frames in flight, a strip of the last frames
  finished (thumbnails, each with its time) and the mean time per frame.

  Three ways to open one, each serving on 127.0.0.1 (a free port unless one
  is given) and opening nothing by itself:

    * `ringtracer render SCENE -o FILE --preview [PORT]` prints the page's
      address on stderr (`--listen ADDR` serves on that address instead);
    * `RingTracer.render(scene, preview: true)` (or a port, or `[port: p,
      listen: addr]`) does the same, and stops the preview when the job ends;
      `preview: preview` watches with a preview you started (`start/1`) and
      stop (`stop/1`) yourself;
    * `open/2` on a job already running (`RingTracer.render_async/2`'s
      handle).

      iex> {:ok, preview} = RingTracer.Preview.start()
      iex> String.starts_with?(RingTracer.Preview.url(preview), "http://127.0.0.1:")
      true
      iex> {:ok, _} = RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 8, children: 2, atoms: 2, preview: preview)
      iex> RingTracer.Preview.stop(preview)
      :ok

  The page (`priv/preview/`) is static HTML, JavaScript and CSS, fed by one
  Server-Sent Events stream (`/events`, see `RingTracer.Preview.Log` for its
  frames); several browsers can watch one job, and one that joins late gets
  everything so far. The server (OTP's `:httpd`, one per preview, see
  `RingTracer.Preview.HTTP`) answers GET for those four paths only, under
  a random first segment that only the printed address holds (loopback is
  open to every local user), and only to requests whose `Host` is its own
  address: it serves that job's picture and figures and nothing else, and
  nothing it receives can start or change anything.

  Cost: the job's parent sends the preview one message per atom and per
  hand-over, children one per protocol event; the preview converts an
  atom's pixels to sRGB base64 once (in the NIF, on a normal scheduler),
  and viewers read the one log. A slow browser lags behind the log and
  holds no buffer; one that stops reading is disconnected (every send has a
  deadline), and a stop drops at once a viewer that is not reading. The
  job, its outputs and the end of `render/2` never wait for a viewer, and
  the job never waits for the preview (`RingTracer.Bench.Preview` measures
  it).
  """

  alias RingTracer.Preview.{Listener, Server}

  @enforce_keys [:pid, :url, :port]
  defstruct [:pid, :url, :port]

  @type t :: %__MODULE__{pid: pid(), url: String.t(), port: :inet.port_number()}

  @doc """
  Starts a preview server, not yet watching a job (it watches one job, the
  first it is given).

  Options: `:port` (default 0: a free one), `:listen` (an address, as a
  tuple or a string, default `{127, 0, 0, 1}`), `:max_viewers` (browsers at
  once, default 32), `:cpu_share` (the most of one core the preview spends
  on atoms while the job runs, default 0.01: on a render too light for
  that, the page lags and catches up when the job ends), `:strip` (of a
  sequence, how many finished frames the page shows, default 12).
  """
  @spec start(keyword()) :: {:ok, t()} | {:error, RingTracer.Error.t()}
  def start(opts \\ []) do
    with {:ok, addr} <- address(Keyword.get(opts, :listen, {127, 0, 0, 1})),
         {:ok, _} <- inets(),
         {:ok, pid} <- server(Keyword.put(opts, :listen, addr)) do
      {addr, port, token} = GenServer.call(pid, :address)

      {:ok,
       %__MODULE__{pid: pid, port: port, url: "http://#{Listener.host(addr)}:#{port}/#{token}/"}}
    end
  end

  defp inets do
    case Application.ensure_all_started(:inets) do
      {:ok, apps} ->
        {:ok, apps}

      {:error, reason} ->
        {:error, RingTracer.Error.new(:preview, "no :inets: #{inspect(reason)}")}
    end
  end

  defp server(opts) do
    case Server.start(opts) do
      {:ok, pid} ->
        {:ok, pid}

      {:error, {:listen, reason}} ->
        {:error, RingTracer.Error.new(:preview, listen_failure(reason, opts))}

      {:error, reason} ->
        {:error,
         RingTracer.Error.new(:preview, "could not start the preview: #{inspect(reason)}")}
    end
  end

  defp listen_failure(reason, opts),
    do: Listener.failure(reason, Keyword.fetch!(opts, :listen), Keyword.get(opts, :port, 0))

  @doc "How many browsers are reading the job's stream now."
  @spec viewers(t()) :: non_neg_integer()
  def viewers(%__MODULE__{pid: pid}), do: GenServer.call(pid, :viewers)

  @doc "The page's address."
  @spec url(t()) :: String.t()
  def url(%__MODULE__{url: url}), do: url

  @doc """
  Stops the preview, after waiting up to `drain_ms` (default 2000) for
  connected browsers to have received the job's final frame: a browser
  whose connection takes no data for 100 ms meanwhile is dropped, not
  waited for, and those still connected after `drain_ms` are dropped too.
  When it returns, the page's listening socket is closed.
  """
  @spec stop(t(), non_neg_integer()) :: :ok
  def stop(%__MODULE__{pid: pid}, drain_ms \\ 2_000) do
    ref = Process.monitor(pid)
    send(pid, {:drain, self(), ref, drain_ms})

    receive do
      {:drained, ^ref} -> GenServer.stop(pid)
      {:DOWN, ^ref, _, _, _} -> :ok
    end

    Process.demonitor(ref, [:flush])
    :ok
  catch
    :exit, _ -> :ok
  end

  @doc """
  Opens a preview of a job already running: `job` is the handle of
  `RingTracer.render_async/2` (a job started on this node) or the pid of a
  job's parent. The page shows the atoms traced so far and everything
  from then on. Takes the options of `start/1`; stop it with `stop/1`.
  """
  @spec open(%{:pid => pid(), optional(atom()) => term()} | pid(), keyword()) ::
          {:ok, t()} | {:error, RingTracer.Error.t()}
  def open(job, opts \\ [])

  def open(%{pid: forwarder}, opts) do
    parents =
      for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Names.jobs()),
          is_pid(pid),
          do: pid

    open_first(parents, forwarder, opts)
  end

  def open(parent, opts) when is_pid(parent), do: open_first([parent], nil, opts)

  defp open_first(parents, progress, opts) do
    with {:ok, preview} <- start(opts) do
      if Enum.any?(parents, &(watch(preview, &1, progress) == :ok)) do
        {:ok, preview}
      else
        stop(preview, 0)
        {:error, RingTracer.Error.new(:preview, "no such job is running on this node")}
      end
    end
  end

  @doc false
  # Watches the job of `parent` (when `progress` is given: only if that job
  # reports its progress to that pid).
  @spec watch(t(), pid(), pid() | nil) :: :ok | {:error, term()}
  def watch(%__MODULE__{pid: pid}, parent, progress \\ nil),
    do: GenServer.call(pid, {:watch, parent, progress})

  @doc false
  # What `render/2`'s `:preview` option does before the job's parent starts
  # (`job`: its id; `nodes`: its other nodes): `{preview, owned?}`, or nil.
  # Then `watch_job/2` once the parent runs.
  @spec for_job(term(), reference(), [node()]) :: {t(), boolean()} | nil
  def for_job(nil, _job, _nodes), do: nil
  def for_job(false, _job, _nodes), do: nil

  def for_job(%__MODULE__{} = preview, job, nodes) do
    case GenServer.call(preview.pid, {:expect, job, nodes}) do
      :ok -> {preview, false}
      {:error, _} -> nil
    end
  end

  def for_job(option, job, nodes) do
    opts =
      case option do
        true -> []
        port when is_integer(port) -> [port: port]
        opts when is_list(opts) -> opts
      end

    # where the address goes: the render's own stderr (a served render's is its client's)
    {announce, opts} = Keyword.pop(opts, :announce, :standard_error)

    case start(opts) do
      {:ok, preview} ->
        # Gone with the render, however it ends (a :timeout kills it).
        send(preview.pid, {:owner, self()})
        IO.puts(announce, "preview: #{preview.url}")
        :ok = GenServer.call(preview.pid, {:expect, job, nodes})
        {preview, true}

      {:error, error} ->
        IO.puts(announce, "preview: #{error.message}")
        nil
    end
  end

  @doc false
  @spec watch_job({t(), boolean()} | nil, pid()) :: :ok
  def watch_job(nil, _parent), do: :ok

  # The caller describes the parent itself, at once: the preview's server
  # runs at low priority, after the job's processes, and a short job can
  # end before it does. Nor does the caller wait for the server.
  def watch_job({preview, _}, parent) do
    described =
      try do
        RingTracer.Job.Parent.describe(parent)
      catch
        :exit, reason -> {:error, {:job_not_running, reason}}
      end

    GenServer.cast(preview.pid, {:described, parent, described})
  end

  @doc false
  @spec after_job({t(), boolean()} | nil) :: :ok
  def after_job({preview, true}), do: stop(preview)
  def after_job(_), do: :ok

  @doc """
  An address to listen on, from a tuple or a string.

      iex> RingTracer.Preview.address("0.0.0.0")
      {:ok, {0, 0, 0, 0}}
      iex> {:error, %RingTracer.Error{}} = RingTracer.Preview.address("nowhere")
  """
  @spec address(term()) ::
          {:ok, :inet.ip_address()} | {:error, RingTracer.Error.t()}
  def address(addr) when is_tuple(addr) and tuple_size(addr) in [4, 8], do: {:ok, addr}

  def address(text) when is_binary(text) do
    case :inet.parse_address(String.to_charlist(text)) do
      {:ok, addr} -> {:ok, addr}
      {:error, _} -> not_an_address(text)
    end
  end

  def address(other), do: not_an_address(inspect(other))

  defp not_an_address(text),
    do: {:error, RingTracer.Error.new(:invalid_option, "not an IP address: #{text}")}
end
