defmodule RingTracer.Farm.Dashboard.HTTP do
  @moduledoc false
  # The only module of the dashboard's `:httpd` server: under `/TOKEN/`, `GET`
  # of the page's three files (by fixed name from `priv/farm`) and of
  # `state.json`, the farm as `RingTracer.Farm.Dashboard.View` shows it, made
  # from `RingTracer.Farm.overview/2` at each request (503 when the head does
  # not answer within 2 s). Everything else is refused as the preview's
  # server refuses it (`RingTracer.Preview.Listener.check/3`: 400, 404, 405,
  # 421). No response has a `Server` header or may be cached.

  alias RingTracer.Farm
  alias RingTracer.Farm.Dashboard.View
  alias RingTracer.Preview.Listener

  @files %{
    "/" => {"index.html", ~c"text/html; charset=utf-8"},
    "/index.html" => {"index.html", ~c"text/html; charset=utf-8"},
    "/dashboard.js" => {"dashboard.js", ~c"text/javascript; charset=utf-8"},
    "/dashboard.css" => {"dashboard.css", ~c"text/css; charset=utf-8"}
  }
  @head_timeout_ms 2_000
  @csp ~c"default-src 'self'; img-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"

  @doc "The folder of the page's files."
  @spec root() :: String.t()
  def root, do: Application.app_dir(:ring_tracer, "priv/farm")

  @doc false
  def unquote(:do)(m) do
    {token, hosts} = Listener.address(Listener.data(m))

    case Listener.check(m, token, hosts) do
      {:error, response} ->
        response

      {:ok, "/state.json"} ->
        case Farm.overview(node(), timeout: @head_timeout_ms) do
          {:ok, overview} ->
            json = View.encode(View.new(overview, node(), System.os_time(:millisecond)))
            Listener.body(json, ~c"application/json", @csp)

          {:error, _} ->
            {:error, response} = Listener.status(503, "the farm head did not answer")
            response
        end

      {:ok, path} when is_map_key(@files, path) ->
        {name, type} = Map.fetch!(@files, path)
        Listener.body(File.read!(Path.join(root(), name)), type, @csp)

      {:ok, _} ->
        {:error, response} = Listener.status(404, "not found")
        response
    end
  end
end
