defmodule RingTracer.CLI do
  @moduledoc false
  # The command line, booted straight from `erl` by the launcher
  # (`bin/ringtracer`), without Mix:
  #
  #     erl -noshell +Bi -pa ... -s Elixir.RingTracer.CLI main -extra render scene.nff -o a.png
  #
  # Commands: `render` (`RingTracer.CLI.Render`), `worker`
  # (`RingTracer.CLI.Worker`), `serve`, `cookie`, and a farm's: `farm`
  # (`RingTracer.CLI.Farm.Head`), `submit` (`RingTracer.CLI.Farm.Submit`),
  # `jobs`, `status`, `wait`, `cancel`, `fetch` (`RingTracer.CLI.Farm.Jobs`).
  # `--help`/`-h` works on each. Exit status: 0 ok,
  # 1 a failure, 2 a usage error, 130/143 interrupted.

  alias RingTracer.CLI.{Args, Console, Paths}

  @commands ~w(render serve worker cookie farm submit jobs status wait cancel fetch)

  @doc "Runs the command in the VM's plain arguments (those after `-extra`) and halts."
  @spec main() :: no_return()
  def main do
    args = Enum.map(:init.get_plain_arguments(), &List.to_string/1)
    # What Mix's config would set (config/config.exs): booted from erl, no config is read.
    Application.put_env(:logger, :level, :info)
    # Interrupts are this process's from the start: one that comes while a
    # scene parses waits in the mailbox instead of stopping the VM with 0.
    RingTracer.CLI.Signals.forward_to(self())
    # halt/1 flushes stdout and stderr before the VM goes.
    System.halt(run(args))
  end

  @doc """
  Runs a command and returns its exit status (the worker runs until the
  VM stops). Interrupts reach it as `RingTracer.CLI.Signals` messages:
  from the VM's signals in a VM of its own (`main/0`), from its client's
  frames when the server runs it.
  """
  @spec run([String.t()]) :: non_neg_integer()

  def run(["render" | argv]), do: RingTracer.CLI.Render.run(argv)

  def run(["worker" | argv]) do
    if help?(argv) do
      IO.write(worker_help())
      0
    else
      case RingTracer.CLI.Worker.start(argv) do
        {:ok, _node, line} ->
          IO.puts(line)

          # Until Ctrl-C or SIGTERM: the children it hosts die with it, and
          # their parents trace their atoms elsewhere; a farm's worker leaves
          # its farm first.
          until_signal(&RingTracer.Farm.leave/0)

        {:error, message} ->
          error("worker", message, 1)
      end
    end
  end

  def run(["farm" | argv]) do
    case RingTracer.CLI.Farm.Head.start(argv) do
      :help ->
        IO.write(RingTracer.CLI.Farm.Head.help())
        0

      {:ok, _node, text} ->
        IO.write(text)

        # Until Ctrl-C or SIGTERM: the queue stays in the head's folder, and
        # a head started again under the same name resumes it.
        until_signal(&RingTracer.Farm.stop_head/0)

      {:error, status, message} ->
        error("farm", message, status)
    end
  end

  def run(["submit" | argv]), do: RingTracer.CLI.Farm.Submit.run(argv)

  def run([command | argv]) when command in ~w(jobs status wait cancel fetch),
    do: RingTracer.CLI.Farm.Jobs.run(command, argv)

  def run(["serve" | argv]) do
    case OptionParser.parse(argv, strict: [socket: :string, help: :boolean], aliases: [h: :help]) do
      {opts, [], []} ->
        if opts[:help], do: serve_help_status(), else: serve(opts)

      {_opts, _args, _invalid} ->
        error("serve", "usage: ringtracer serve [--socket PATH]", 2)
    end
  end

  def run(["cookie" | argv]) do
    cond do
      help?(argv) ->
        IO.write(cookie_help())
        0

      length(argv) > 1 ->
        error("cookie", "usage: ringtracer cookie [PATH]", 2)

      true ->
        path =
          if argv == [],
            do: RingTracer.Cluster.Cookie.default_path(),
            else: Paths.expand(hd(argv))

        case RingTracer.Cluster.Cookie.create(path) do
          {:ok, path} ->
            IO.puts("wrote a new cookie to #{path} (mode 0600)")
            0

          {:error, e} ->
            error("cookie", e.message, 1)
        end
    end
  end

  def run(["--version"]) do
    :ok = load(:ring_tracer)
    build = RingTracer.Cluster.Build.identity()
    IO.puts("ringtracer #{build.version} (build #{RingTracer.Cluster.Build.short(build)})")
    0
  end

  def run([help]) when help in ["help", "--help", "-h"] do
    IO.write(help())
    0
  end

  def run([]) do
    IO.write(Console.err(), help())
    2
  end

  def run([other | _]) do
    hint =
      case Args.suggest(other, Enum.map(@commands, &{String.to_atom(&1), nil})) do
        nil -> ""
        "--" <> best -> " (did you mean #{best}?)"
      end

    error(
      "",
      "unknown command #{other}#{hint}; commands: #{Enum.join(@commands, ", ")} (see --help)",
      2
    )
  end

  defp serve_help_status do
    IO.write(serve_help())
    0
  end

  defp serve(opts) do
    path = Paths.expand(opts[:socket] || System.get_env("RINGTRACER_SOCKET") || default_socket())

    with {:ok, _} <- Application.ensure_all_started(:ring_tracer),
         :ok <- warm_up(),
         {:ok, pid} <- RingTracer.CLI.Server.start_link(path, &run/1) do
      IO.puts("ringtracer serve: rendering for this user's commands on #{path} (Ctrl-C stops)")

      receive do
        {RingTracer.CLI.Signals, signal} ->
          RingTracer.CLI.Server.stop(pid)
          RingTracer.CLI.Signals.exit_status(signal)
      end
    else
      {:error, message} when is_binary(message) -> error("serve", message, 1)
      {:error, reason} -> error("serve", inspect(reason), 1)
    end
  end

  defp default_socket do
    base = System.get_env("XDG_RUNTIME_DIR") || Path.join(System.user_home!(), ".cache")
    Path.join([base, "ringtracer", "serve.sock"])
  end

  # What the first command would otherwise load: every module of OTP's
  # kernel and stdlib, of Elixir and of the application, and the kernel's
  # first trace. Loaded now, they need no descriptor later: out of them
  # (emfile), a module loaded on first use fails, and the logger's handler
  # with it.
  defp warm_up do
    for app <- [:kernel, :stdlib, :elixir, :logger, :ring_tracer],
        {:ok, modules} = :application.get_key(app, :modules),
        module <- modules,
        do: Code.ensure_loaded(module)

    scene = Path.join(:code.priv_dir(:ring_tracer), "scenes/whitted.toml")
    _ = RingTracer.render(scene, width: 8, height: 8)
    :ok
  end

  defp help?(argv), do: Enum.any?(argv, &(&1 in ["--help", "-h"]))

  defp error(command, message, status) do
    prefix = if command == "", do: "ringtracer", else: "ringtracer #{command}"
    IO.puts(Console.err(), "#{prefix}: #{message}")
    status
  end

  @doc "The launcher's own help."
  @spec help() :: String.t()
  def help do
    """
    Usage: ringtracer COMMAND [options]      (ringtracer COMMAND --help for each)

    Commands:
      render SCENE --out FILE   render a scene to an image (.png or .exr)
      serve                     keep a render node running: later renders start at once
      worker --sname NAME       a node that hosts children of renders started elsewhere
      cookie [PATH]             make a cookie file, mode 0600 (default ~/.erlang.cookie)
      tls ca DIR | tls node CA_DIR OUT_DIR [HOST...]   certificates for a TLS cluster
      test                      every check and test (Rust and Elixir, dialyzer)
      setup                     install what is missing (Debian packages) and build
      mix ARGS...               any mix command, with the set-up done

    A render farm (docs/farm.md):
      farm [--sname NAME]       a farm's head: a queue of jobs that workers join
      worker --join HEAD        a worker of that farm (joins again when the head restarts)
      submit SCENE --out FILE --farm HEAD   queue a still or a sequence; its frames come back
      jobs | status ID | wait ID | cancel ID | fetch ID   --farm HEAD: the queue, one job

    Examples:
      ringtracer render priv/scenes/balls_s2.nff --out balls.png
      ringtracer worker --sname w1 &
      ringtracer render scene.toml -o scene.png --nodes w1@localhost
      ringtracer farm &
      ringtracer worker --join farm@localhost &
      ringtracer submit scene.toml -o scene.png --farm farm@localhost

    Exit status: 0 ok, 1 failed, 2 usage error, 130 interrupted, 143 terminated.
    """
  end

  defp worker_help do
    """
    Usage: ringtracer worker --sname NAME [options]
           ringtracer worker --join HEAD [--tags a,b] [--slots N] [--speed F] [options]

    A node that hosts children of renders started on other nodes, until stopped (Ctrl-C).

      --sname NAME            a short name (on loopback: NAME@localhost)
      --name NAME@HOST        a long name
      --cookie-file PATH      the cookie, in a file only you can read (default ~/.erlang.cookie)
      --listen ADDR           the address to listen on (default 127.0.0.1: this machine only)
      --ports MIN-MAX         the distribution listener's ports, for firewalls
      --tls DIR               the TLS certificates (default: your own, made on first use in
                              ~/.config/ringtracer/tls; see ringtracer tls)
      --insecure-plain        plain TCP distribution instead of TLS: whoever answers on port
                              4369 (any local user who starts epmd first) or sits on the
                              network can read and alter everything, and run code here
      --allow-foreign-epmd    with --insecure-plain, start even when epmd is another user's

    A farm's worker (see ringtracer farm --help):
      --join HEAD             join the farm whose head is HEAD (farm@localhost), now or
                              once it is up, and again whenever it restarts; --sname
                              may then be left out (a name is made up)
      --tags a,b              tags a job may ask its workers to have
      --slots N               children hosted for a job (default: one per core)
      --speed F               emulate a machine F times slower (1-#{RingTracer.Job.Slowdown.max()}, for tests)

    Distribution runs over TLS with mutual authentication by default, loopback included.

    Examples:
      ringtracer worker --sname w1 &
      ringtracer render priv/scenes/balls_s2.nff -o b.png --nodes w1@localhost
      ringtracer worker --join farm@localhost --slots 4 --tags big-mem &
    """
  end

  defp serve_help do
    """
    Usage: ringtracer serve [--socket PATH]

    Keeps a render node running for this user, until stopped (Ctrl-C). While it runs,
    `ringtracer render` hands its work to it instead of booting a VM of its own, so the
    render starts at once. Output, progress, Ctrl-C and exit status are the same. A
    server that does not answer within 2 s (stopped, busy) is left for a VM of the
    render's own.
    Renders on other nodes (--nodes, --tls, ...) still boot their own VM.

      --socket PATH           the Unix socket; its folder is mode 0700. Default, one per
                              checkout: $XDG_RUNTIME_DIR/ringtracer/serve-N.sock, else
                              ~/.cache/ringtracer/serve-N.sock (N: a checksum of the
                              checkout's path); RINGTRACER_SOCKET overrides it, for
                              `ringtracer render` too
      RINGTRACER_SERVER=off   in the environment of `ringtracer render`: never use a server
      RINGTRACER_SERVER=only  fail rather than boot a VM of its own

    Example:
      ringtracer serve &
      ringtracer render priv/scenes/whitted.toml -o whitted.png
    """
  end

  defp cookie_help do
    """
    Usage: ringtracer cookie [PATH]

    Writes a new random cookie to PATH (default ~/.erlang.cookie), mode 0600; refuses to
    replace an existing file. Copy it, keeping its mode, to every machine of the cluster:
    whoever has it can run any code on every node.
    """
  end

  defp load(app) do
    case Application.load(app) do
      :ok -> :ok
      {:error, {:already_loaded, ^app}} -> :ok
    end
  end

  # Runs until Ctrl-C or SIGTERM, then `stop` and the signal's exit status.
  defp until_signal(stop) do
    receive do
      {RingTracer.CLI.Signals, signal} ->
        :ok = stop.()
        RingTracer.CLI.Signals.exit_status(signal)
    end
  end
end
