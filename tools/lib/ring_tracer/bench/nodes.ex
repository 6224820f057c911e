defmodule RingTracer.Bench.Nodes do
  @help """
  One node against three on this machine.

      mix ring_tracer.bench nodes [--scene FILE] [--children 6] [--runs 3]

  Starts two peer nodes on this machine and renders the same job on this
  node alone and on all three, printing both makespans, their ratio and the
  scene bytes each node received (shipped once per node).
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "nodes [--scene FILE] [--children 6] [--runs 3]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, _, _} =
      OptionParser.parse(argv, strict: [scene: :string, children: :integer, runs: :integer])

    scene = opts[:scene] || "priv/scenes/spd/balls_s4.nff"
    children = opts[:children] || 6
    runs = opts[:runs] || 3
    Mix.Task.run("app.start")
    RingTracer.Cluster.Distribution.start!(generate: true)
    peers = for name <- ["bench_w1", "bench_w2"], do: RingTracer.LocalCluster.start(name)
    nodes = Enum.map(peers, &elem(&1, 1))

    info(
      "#{scene}, #{children} children x 16 atoms, median of #{runs}; 3 nodes = this one and 2 peers on the same #{System.schedulers_online()} cores"
    )

    one = median_result(runs, fn -> RingTracer.render(scene, children: children) end)

    three =
      median_result(runs, fn -> RingTracer.render(scene, children: children, nodes: nodes) end)

    rows =
      for {label, r} <- [{"1 node", one}, {"3 nodes", three}] do
        bytes = r.nodes |> Enum.map_join(" ", fn {n, s} -> "#{n}:#{s.scene_bytes}" end)
        [label, fmt(r.elapsed_us / 1000), fmt(r.elapsed_us / one.elapsed_us), bytes]
      end

    print_table(~w(layout makespan_ms vs_1_node scene_bytes_per_node), rows)
    Enum.each(peers, fn {peer, _} -> RingTracer.LocalCluster.stop(peer) end)
  end
end
