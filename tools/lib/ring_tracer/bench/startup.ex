defmodule RingTracer.Bench.Startup do
  @help """
  The whole command against POV-Ray's whole process.

      mix ring_tracer.bench startup [--scenes a,b] [--runs 5] [--size 512]

  Runs `bin/ringtracer render SCENE` at `--size` (quiet, with `--stats`)
  twice, once booting a VM of its own and once through a `ringtracer
  serve` the benchmark starts, and POV-Ray's whole process on the matching
  `.pov`, alternately, and prints for each SPD scene the time from exec to
  the first atom's pixels (from the job's `started_at_us` and first atom in
  the statistics), the whole-process times and their ratios to POV-Ray's.
  Targets, through the server: first atom at most 0.2 s, whole command at
  most 0.4x POV-Ray's.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.Bench.PovRay

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "startup [--scenes a,b] [--runs 5] [--size 512]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv,
        strict: [scenes: :string, dir: :string, pov_dir: :string, runs: :integer, size: :integer]
      )

    dir = opts[:dir] || "priv/scenes/spd"
    pov_dir = opts[:pov_dir] || PovRay.default_dir()
    scenes = if s = opts[:scenes], do: String.split(s, ","), else: PovRay.spd_scenes()
    runs = opts[:runs] || 5
    size = opts[:size] || 512
    povray = PovRay.executable()
    launcher = Path.expand("bin/ringtracer")
    tmp = RingTracer.Bench.private_tmp_dir!("ringtracer-bench-startup")
    # The launcher builds itself first if it is stale: not part of any run.
    {_, 0} = System.cmd(launcher, ["render", "--help"], stderr_to_stdout: true)

    info(
      "#{size}x#{size}, whole processes, median of #{runs} (alternating); " <>
        "first atom: from exec to the first atom's pixels reaching the parent; " <>
        "own VM: the command boots one; served: through `ringtracer serve`; " <>
        "povray +WT2 -D -A" <> if(povray, do: "", else: " (povray not installed)")
    )

    socket = Path.join([tmp, "serve-#{System.pid()}", "serve.sock"])
    server = start_server(launcher, socket)

    header = ~w(scene first_atom_s ours_s served_first_s served_s pov_s ours/pov served/pov)
    own_vm = [{"RINGTRACER_SERVER", "off"}]
    served = [{"RINGTRACER_SOCKET", socket}, {"RINGTRACER_SERVER", "only"}]

    rows =
      try do
        for name <- scenes do
          scene = Path.expand(Path.join(dir, name <> ".nff"))
          pov = Path.expand(Path.join(pov_dir, name <> ".pov"))

          ours = fn env ->
            stats = Path.join(tmp, "stats.json")

            args =
              ~w(render #{scene} -o #{tmp}/ours.png --width #{size} --height #{size} -q --stats #{stats})

            t0 = System.system_time(:microsecond)
            {_, 0} = System.cmd(launcher, args, stderr_to_stdout: true, env: env)
            whole = System.system_time(:microsecond) - t0
            summary = stats |> File.read!() |> :jiffy.decode([:return_maps])
            {whole, summary["started_at_us"] + summary["first_atom_us"] - t0}
          end

          theirs = fn ->
            if povray && File.exists?(pov) do
              t0 = System.monotonic_time(:microsecond)

              {_, _} =
                System.cmd(
                  povray,
                  ~w(+I#{pov} +O#{tmp}/pov.png +W#{size} +H#{size} -D -A +WT2),
                  stderr_to_stdout: true
                )

              System.monotonic_time(:microsecond) - t0
            end
          end

          samples = for _ <- 1..runs, do: {ours.(own_vm), ours.(served), theirs.()}
          pick = fn f -> median(Enum.map(samples, f)) end
          pov_samples = for {_, _, p} <- samples, p != nil, do: p
          pov_us = if pov_samples != [], do: median(pov_samples)
          whole = pick.(fn {{w, _}, _, _} -> w end)
          s_whole = pick.(fn {_, {w, _}, _} -> w end)

          [
            name,
            secs(pick.(fn {{_, f}, _, _} -> f end)),
            secs(whole),
            secs(pick.(fn {_, {_, f}, _} -> f end)),
            secs(s_whole),
            pov_us && secs(pov_us),
            pov_us && fmt(whole / pov_us),
            pov_us && fmt(s_whole / pov_us)
          ]
        end
      after
        stop_server(server)
        File.rm_rf(tmp)
      end

    print_table(header, rows)
    info("targets: served_first_s <= 0.2, served/pov <= 0.4")
  end

  # `ringtracer serve` on `socket`; ready once the socket appears (after its warm-up).
  defp start_server(launcher, socket) do
    File.rm(socket)

    port =
      Port.open({:spawn_executable, launcher}, [
        :binary,
        :exit_status,
        args: ["serve"],
        env: [{~c"RINGTRACER_SOCKET", String.to_charlist(socket)}]
      ])

    wait_for_socket(socket, 600)
    port
  end

  defp wait_for_socket(socket, 0), do: Mix.raise("ringtracer serve did not start on #{socket}")

  defp wait_for_socket(socket, n) do
    unless File.exists?(socket) do
      Process.sleep(50)
      wait_for_socket(socket, n - 1)
    end
  end

  defp stop_server(port) do
    {:os_pid, pid} = Port.info(port, :os_pid)
    System.cmd("kill", ["-TERM", Integer.to_string(pid)])

    receive do
      {^port, {:exit_status, _}} -> :ok
    after
      10_000 -> :ok
    end
  end
end
