defmodule RingTracer.CLI.Farm.Head do
  @moduledoc false
  # `ringtracer farm [--sname NAME] [--dir DIR] [options]`: starts a farm's
  # head (`RingTracer.Farm.start_head/1`) on a distributed node, loopback and
  # TLS by default as `ringtracer worker`, prints its name and how to join it,
  # and runs until stopped (Ctrl-C or SIGTERM: 130 or 143).
  #
  # ## Options
  #
  #   * `--sname NAME` — the head's short name (default `farm`: on loopback
  #     `farm@localhost`); the queue belongs to the name, so a head restarted
  #     must keep it
  #   * `--dir DIR` — the head's folder: the queue (Mnesia) and the frames
  #     done. Default `$XDG_STATE_HOME/ringtracer/farm/NODE` (`~/.local/state`
  #     without it), every folder made mode 0700
  #   * `--dashboard-port PORT` — the dashboard's port (default a free one);
  #     it listens where the node does (`--listen`), behind a random token
  #   * `--no-dashboard` — no dashboard
  #   * the distribution switches of `RingTracer.CLI.Worker` (`--name`,
  #     `--cookie-file`, `--listen`, `--ports`, `--tls`, `--insecure-plain`)

  alias RingTracer.CLI.{Args, Paths}
  alias RingTracer.CLI.Worker

  @switches [dir: :string, dashboard_port: :integer, no_dashboard: :boolean] ++
              Worker.switches()

  @doc "The text of `ringtracer farm --help`."
  @spec help() :: String.t()
  def help do
    """
    Usage: ringtracer farm [--sname NAME] [--dir DIR] [options]

    Starts a farm's head: a node that keeps a queue of jobs (in Mnesia, on disk) and
    runs them on the workers that join it, until stopped (Ctrl-C). Prints its name
    and how to join it. Restarted under the same name, it resumes every job where it
    stopped (kill -9 included): no frame done is rendered again.

      --sname NAME            the head's name (default farm: farm@localhost on loopback)
      --dir DIR               its folder: the queue and the frames done (default
                              $XDG_STATE_HOME/ringtracer/farm/NODE, or ~/.local/state/...;
                              made mode 0700)
      --name NAME@HOST        a long name, for a head other machines reach
      --cookie-file PATH      the cookie, in a file only you can read (default ~/.erlang.cookie)
      --listen ADDR           the address to listen on (default 127.0.0.1: this machine only)
      --ports MIN-MAX         the distribution listener's ports, for firewalls
      --tls DIR               the TLS certificates (default: your own, made on first use)
      --insecure-plain        plain TCP distribution instead of TLS (see ringtracer worker --help)
      --dashboard-port PORT   the dashboard's port (default a free one; it listens where
                              the node does, behind a random token in its address)
      --no-dashboard          no dashboard

    Every node of a farm (head, workers, submitters) uses the same cookie file and
    certificates of one CA (ringtracer cookie, ringtracer tls).

    Example:
      ringtracer farm &
      ringtracer worker --join farm@localhost &
      ringtracer submit priv/scenes/balls_s2.nff -o balls.png --farm farm@localhost
    """
  end

  @doc """
  Parses `argv`, makes this node distributed and starts the head. Returns
  its node name and the lines to print, or the exit status and a message.
  """
  @spec start([String.t()]) ::
          {:ok, node(), String.t()} | :help | {:error, pos_integer(), String.t()}
  def start(argv) do
    case Args.parse(argv, @switches, %{}) do
      :help ->
        :help

      {:error, message} ->
        {:error, 2, message}

      {:ok, _opts, [_ | _] = extra} ->
        {:error, 2, "unexpected argument(s): #{Enum.join(extra, " ")}"}

      {:ok, opts, []} ->
        opts = Paths.expand(opts, [:cookie_file, :tls, :dir])
        opts = if opts[:name] || opts[:sname], do: opts, else: [sname: "farm"] ++ opts
        worker_opts = Keyword.drop(opts, [:dir, :dashboard_port, :no_dashboard])

        with {:ok, node} <- distribution(worker_opts),
             {:ok, dir} <- dir(opts[:dir], node),
             {:ok, _} <-
               failed(RingTracer.Farm.start_head(dir: dir, dashboard: dashboard(opts))) do
          {:ok, node, ready(node, dir, opts)}
        end
    end
  end

  # On by default: loopback unless --listen widens the node, a random token.
  defp dashboard(opts) do
    if opts[:no_dashboard],
      do: false,
      else: [port: opts[:dashboard_port] || 0] ++ Keyword.take(opts, [:listen])
  end

  defp distribution(opts) do
    case RingTracer.CLI.Worker.distribute(opts) do
      {:ok, node} -> {:ok, node}
      {:error, message} -> {:error, 1, message}
    end
  end

  defp failed({:error, %RingTracer.Error{message: message}}), do: {:error, 1, message}
  defp failed(ok), do: ok

  defp ready(node, dir, opts) do
    queued =
      case RingTracer.Farm.jobs(node) do
        {:ok, jobs} -> Enum.count(jobs, &(&1.state in [:queued, :running]))
        _ -> 0
      end

    dashboard =
      case RingTracer.Farm.dashboard_url(node) do
        {:ok, url} -> "dashboard:  #{url}\n"
        _ -> ""
      end

    """
    RingTracer farm head #{node} ready (queue and frames in #{dir}; #{Worker.credentials(opts)})
    #{if queued > 0, do: "#{queued} job(s) resumed from the queue\n", else: ""}join it:    ringtracer worker --join #{node}
    submit:     ringtracer submit SCENE --out FILE --farm #{node}
    the queue:  ringtracer jobs --farm #{node}
    """ <> dashboard
  end

  @doc """
  The head's folder: `dir` as given, else the default under the user's
  state folder, each folder of it that is missing made mode 0700.
  """
  @spec dir(Path.t() | nil, node()) :: {:ok, Path.t()} | {:error, 1, String.t()}
  def dir(nil, node) do
    state =
      case System.get_env("XDG_STATE_HOME") do
        nil -> Path.join([System.user_home!(), ".local", "state"])
        "" -> Path.join([System.user_home!(), ".local", "state"])
        path -> Path.expand(path)
      end

    path = Path.join([state, "ringtracer", "farm", Atom.to_string(node)])

    # the folders above the head's own; the head makes (and checks) its own
    missing =
      path
      |> Path.dirname()
      |> ancestors()
      |> Enum.reject(&File.exists?/1)

    Enum.reduce_while(missing, {:ok, path}, fn folder, acc ->
      case RingTracer.Output.private_dir(folder) do
        :ok -> {:cont, acc}
        {:error, reason} -> {:halt, {:error, 1, "#{folder}: #{format(reason)}"}}
      end
    end)
  end

  def dir(dir, _node), do: {:ok, dir}

  defp ancestors(path) do
    path
    |> Path.split()
    |> Enum.scan(&Path.join(&2, &1))
  end

  defp format(reason) when is_atom(reason), do: :file.format_error(reason) |> to_string()
  defp format(reason), do: reason
end
