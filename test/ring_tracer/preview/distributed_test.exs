defmodule RingTracer.Preview.DistributedTest do
  # Children on another node: their help offers reach the preview through a
  # handler on their node, and the page names each child's node.
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 120_000

  alias RingTracer.LocalCluster, as: Peers

  setup_all do
    {peer, n} = Peers.start("pv")
    on_exit(fn -> Peers.stop(peer) end)
    {:ok, node: n}
  end

  test "a preview of a job on two nodes gets every child's events and nodes", %{node: n} do
    {:ok, preview} = RingTracer.Preview.start()

    {:ok, result} =
      RingTracer.render("priv/scenes/tetra_s1.nff",
        width: 32,
        height: 24,
        nodes: [n],
        children: 4,
        atoms: 6,
        speeds: [1, 30],
        preview: preview
      )

    {:ok, {{_, 200, _}, _, body}} =
      :httpc.request(:get, {String.to_charlist(preview.url <> "events"), []}, [], [])

    frames =
      for f <- String.split(to_string(body), "\n\n", trim: true) do
        [_, name, data] = Regex.run(~r/\Aid: \d+\nevent: (\w+)\ndata: (.*)\z/s, f)
        {name, :jiffy.decode(data, [:return_maps, :use_nil])}
      end

    [job] = for {"job", j} <- frames, do: j
    assert job["nodes"] == Enum.map(result.children, &Atom.to_string(&1.node))
    assert Atom.to_string(n) in job["nodes"]

    evs = for {"ev", e} <- frames, do: {e["kind"], e["from"], e["to"], e["at"]}
    want = for e <- result.events, do: {Atom.to_string(e.kind), e.from, e.to, e.at_us}
    assert Enum.sort(evs) == Enum.sort(want)
    assert Enum.any?(evs, fn {_, from, _, _} -> rem(from, 2) == 1 end)

    RingTracer.Preview.stop(preview, 0)
    # The handler on the other node is gone with the preview.
    handlers =
      :erpc.call(n, :ets, :match_object, [
        RingTracer.Telemetry,
        {:_, {RingTracer.Preview.Server, :_, :_}, :_, :_}
      ])

    assert handlers == []
  end
end
