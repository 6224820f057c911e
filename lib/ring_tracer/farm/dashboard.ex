defmodule RingTracer.Farm.Dashboard do
  @moduledoc false
  # A farm's dashboard, on the head (`RingTracer.Farm.start_head/1`'s
  # `:dashboard`): a page of the farm's workers (speed, slots, tags, state,
  # current job), its jobs (state, frames done of all, progress, time left,
  # a link to each running job's live preview) and its queue.
  #
  # Served by the guarded `:httpd` of the live preview
  # (`RingTracer.Preview.Listener`): on 127.0.0.1 unless `:listen` says
  # otherwise, under a random first segment (`:token`, made by
  # `start_head/1` and kept across the head's restarts, so the address stays
  # the same), to requests whose `Host` is its own address only; `GET` only.
  # The page (`priv/farm/`: plain HTML, JavaScript and CSS, nothing loaded
  # from elsewhere) polls `state.json` (`RingTracer.Farm.Dashboard.View`)
  # once a second; nothing the dashboard receives can change the farm.

  use GenServer

  alias RingTracer.{Error, Names}
  alias RingTracer.Preview.Listener

  # Connections kept at most (there are no long-lived streams: every
  # request is answered at once), and httpd's own backstop.
  @max_waiting 64
  @sweep_ms 100
  @max_connections 256

  @enforce_keys [:server, :secret, :url]
  defstruct [:server, :secret, :url, waiting: %{}]

  @type t :: %__MODULE__{
          server: Listener.t(),
          secret: :ets.tid(),
          url: String.t(),
          waiting: %{pid() => integer()}
        }

  @doc """
  The options of `start_head/1`'s `:dashboard`, checked, with a token and a
  port that stay the same across the head's restarts.

  ## Options

    * `:port` — default 0: a free one, picked now
    * `:listen` — the address, a tuple or a string (default 127.0.0.1)
  """
  @spec options(true | keyword()) :: {:ok, keyword()} | {:error, Error.t()}
  def options(true), do: options([])

  def options(opts) when is_list(opts) do
    with {:ok, addr} <- RingTracer.Preview.address(Keyword.get(opts, :listen, {127, 0, 0, 1})),
         {:ok, port} <- port(Keyword.get(opts, :port, 0), addr) do
      {:ok, [listen: addr, port: port, token: Listener.token()]}
    end
  end

  def options(other),
    do:
      {:error,
       Error.new(
         :invalid_option,
         ":dashboard must be true or [port: p, listen: address], got: #{inspect(other)}"
       )}

  # Port 0: a free port picked once, so that a restart serves at the same address.
  defp port(0, addr) do
    case :gen_tcp.listen(0, ip: addr) do
      {:ok, socket} ->
        {:ok, port} = :inet.port(socket)
        :gen_tcp.close(socket)
        {:ok, port}

      {:error, reason} ->
        {:error, Error.new(:farm, "dashboard: " <> Listener.failure(reason, addr, 0))}
    end
  end

  defp port(port, _addr) when is_integer(port) and port in 1..65_535, do: {:ok, port}

  defp port(other, _addr),
    do: {:error, Error.new(:invalid_option, "dashboard: not a port: #{inspect(other)}")}

  @doc false
  @spec child_spec(keyword()) :: Supervisor.child_spec()
  def child_spec(opts), do: %{id: __MODULE__, start: {__MODULE__, :start_link, [opts]}}

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: Names.farm_dashboard())

  @doc """
  The dashboard's address, with its token, of the head on `head`: `{:error,
  _}` when that head runs no dashboard.
  """
  @spec url(node()) :: {:ok, String.t()} | {:error, Error.t()}
  def url(head) do
    {:ok, GenServer.call(Names.farm_dashboard(head), :url, 10_000)}
  catch
    :exit, _ -> {:error, Error.new(:farm, "the farm head #{head} runs no dashboard")}
  end

  @doc false
  @spec running?() :: boolean()
  def running?, do: Process.whereis(Names.farm_dashboard()) != nil

  @impl true
  def init(opts) do
    Process.flag(:trap_exit, true)
    addr = Keyword.fetch!(opts, :listen)
    token = Keyword.fetch!(opts, :token)
    secret = Listener.secret(token, addr)

    with {:ok, _} <- Application.ensure_all_started(:inets),
         {:ok, server} <-
           Listener.start(RingTracer.Farm.Dashboard.HTTP, secret,
             listen: addr,
             port: Keyword.fetch!(opts, :port),
             name: ~c"ringtracer-farm",
             root: RingTracer.Farm.Dashboard.HTTP.root(),
             max_clients: @max_connections
           ) do
      Process.send_after(self(), :sweep, @sweep_ms)
      url = "http://#{Listener.host(addr)}:#{server.port}/#{token}/"
      {:ok, %__MODULE__{server: server, secret: secret, url: url}}
    else
      {:error, {:listen, reason}} ->
        {:stop, Error.new(:farm, "dashboard: " <> Listener.failure(reason, addr, opts[:port]))}

      {:error, reason} ->
        {:stop, Error.new(:farm, "dashboard: could not start: #{inspect(reason)}")}
    end
  end

  @impl true
  def handle_call(:url, _from, state), do: {:reply, state.url, state}

  @impl true
  def handle_info(:sweep, state) do
    Process.send_after(self(), :sweep, @sweep_ms)
    {:noreply, %{state | waiting: Listener.sweep(state.server, state.waiting, %{}, @max_waiting)}}
  end

  def handle_info(_other, state), do: {:noreply, state}

  @impl true
  def terminate(_reason, state) do
    :ets.delete(state.secret)
    Listener.close(state.server)
  end
end
