defmodule RingTracer.Bench.Limits do
  @help """
  Every documented maximum at full size.

      mix ring_tracer.bench limits [--quick]

  Runs each documented maximum of `RingTracer.Options` and the kernel's
  image size at full size (`--quick`: a sixteenth): 16,384 children,
  1,048,576 atoms (simulated on one child, and real on one child and on 64
  children: a child's cost per atom does not grow with its queue), and a 64 Mpixel
  image, printing time, the VM's memory growth and the outcome.
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  import RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "limits [--quick]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} = OptionParser.parse(argv, strict: [quick: :boolean])
    Mix.Task.run("app.start")
    max = RingTracer.Options.maxima()
    # --quick: a sixteenth of each, for a check that the command itself works.
    q = if opts[:quick], do: 16, else: 1
    scene = "priv/scenes/balls_s1.nff"
    side = div(8192, if(q == 1, do: 1, else: 4))

    info(
      "every documented maximum at #{if q == 1, do: "full size", else: "1/#{q} size (--quick)"}; #{vm()}"
    )

    cases = [
      {"children", "#{div(max.children, q)} children x 1 atom, 256x256",
       fn ->
         RingTracer.render(scene,
           children: div(max.children, q),
           atoms: 1,
           width: 256,
           height: 256
         )
       end},
      {"atoms", "1 child x #{div(max.atoms, q)} atoms (simulated, 1 us each)",
       fn -> RingTracer.simulate(children: 1, atoms: div(max.atoms, q), costs: 1) end},
      {"atoms", "1 child x #{div(max.atoms, q)} atoms, 1024x1024",
       fn ->
         RingTracer.render(scene, children: 1, atoms: div(max.atoms, q), width: 1024, height: 1024)
       end},
      {"atoms", "64 children x #{div(max.atoms, 64 * q)} atoms, 1024x1024",
       fn ->
         RingTracer.render(scene,
           children: 64,
           atoms: div(max.atoms, 64 * q),
           width: 1024,
           height: 1024
         )
       end},
      {"pixels", "#{side}x#{side} (#{div(side * side, 1_048_576)} Mpixel), 8 children",
       fn ->
         RingTracer.render(scene, children: 8, atoms: 64, width: side, height: side, depth: 2)
       end}
    ]

    rows =
      for {what, job, fun} <- cases do
        :erlang.garbage_collect()
        before = :erlang.memory(:total)
        {us, result} = :timer.tc(fun)

        outcome =
          case result do
            {:ok, r} -> "ok, #{length(r.atoms)} atoms"
            {:error, e} -> "ERROR: #{e.message}"
          end

        peak = :erlang.memory(:total) - before
        [what, job, secs(us), "#{div(max(peak, 0), 1_048_576)} MiB", outcome]
      end

    print_table(~w(maximum job seconds vm_growth outcome), rows)
  end
end
