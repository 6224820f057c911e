defmodule RingTracer.Bench.Limits do
  @help """
  Every documented maximum at full size.

      mix ring_tracer.bench limits [--quick]

  Runs each documented maximum of `RingTracer.Options` and the kernel's
  image size at full size (`--quick`: a sixteenth): 16,384 children,
  1,048,576 atoms (simulated on one child, and real on one child and on 64
  children: a child's cost per atom does not grow with its queue), and a 64 Mpixel
  image, printing time, the VM's memory growth and the outcome; then one
  child's cost per atom at 65,536, 262,144 and 1,048,576 one-pixel atoms.
  """
  @moduledoc false
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
    per_atom(q)
  end

  # One child, one pixel per atom, at three sizes four times apart: the
  # whole call's and the makespan's microseconds per atom, which stay flat
  # when nothing a job does grows faster than its atom count.
  defp per_atom(q) do
    info("one child, one pixel an atom (balls_s1): microseconds per atom")

    rows =
      for side <- [256, 512, 1024] do
        n = div(side * side, q)
        w = div(side, if(q == 1, do: 1, else: 4))
        :erlang.garbage_collect()

        {us, {:ok, r}} =
          :timer.tc(fn ->
            RingTracer.render("priv/scenes/balls_s1.nff",
              children: 1,
              atoms: n,
              width: w,
              height: w
            )
          end)

        Enum.map(
          [n, "#{w}x#{w}", Float.round(us / n, 1), Float.round(r.elapsed_us / n, 1)],
          &to_string/1
        )
      end

    print_table(~w(atoms image call_us_per_atom makespan_us_per_atom), rows)
  end
end
