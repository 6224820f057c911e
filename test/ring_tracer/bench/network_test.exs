defmodule RingTracer.Bench.NetworkTest do
  # The network benchmark's set-up, small: the parent's namespace and two
  # workers' namespaces behind the delaying relay, one delay. Skipped, with
  # the reason, only where network namespaces cannot be created (tried when
  # this file loads).
  use ExUnit.Case, async: false

  alias RingTracer.Bench.Network.{Lab, Remote}
  alias RingTracer.TestScenes

  @moduletag :network
  @moduletag timeout: 120_000

  @netns Lab.probe()
  if @netns != :ok do
    {:error, why} = @netns
    IO.puts(:stderr, "network benchmark test skipped: #{why}")
    @moduletag skip: "network namespaces cannot be created here: #{why}"
  end

  @delay_ms 10
  @scene "balls_s2.nff"

  test "two worker namespaces behind a 10 ms relay: links, round trip, traffic, identical images" do
    reference = TestScenes.reference(@scene, 96, 72)
    scene = TestScenes.path(@scene)

    Lab.with_lab([workers: 2, rate: "100mbit", delay_ms: @delay_ms], fn lab ->
      namespaces = [lab.hub | Enum.map(lab.nodes, & &1.ns)]
      {listed, 0} = System.cmd("ip", ["netns", "list"])
      for ns <- namespaces, do: assert(listed =~ ns)

      # Both ends of every link have the bandwidth limit.
      for n <- lab.nodes do
        {hub, 0} = System.cmd("tc", ~w(-n #{lab.hub} qdisc show dev h#{n.index}))
        {own, 0} = System.cmd("tc", ~w(-n #{n.ns} qdisc show dev eth0))
        assert hub =~ "tbf" and hub =~ "100Mbit"
        assert own =~ "tbf" and own =~ "100Mbit"
      end

      # The delay is in the path: a round trip takes two one-way delays.
      for {_w, ms} <- Lab.rtt_ms(lab, 3), do: assert(ms >= 2 * @delay_ms)

      for strategy <- RingTracer.Strategies.names() do
        before = Lab.counters(lab)

        opts = [
          strategy: strategy,
          nodes: lab.workers,
          local: false,
          children_per_node: 2,
          atoms: 4,
          width: 96,
          height: 72,
          speeds: [1, 1, 3, 1]
        ]

        {:ok, r} = Lab.call(lab.parent, Remote, :render, [scene, opts, 2, true])
        after_ = Lab.counters(lab)

        assert r.pixels == reference, "#{strategy}: the image differs from a local render"
        assert Enum.sort(r.nodes) == Enum.sort(lab.workers)
        # The pixels crossed the parent's link, as each atom's compressed floats.
        parent = lab.parent.name
        assert after_[parent].recv_oct - before[parent].recv_oct >= wire_bytes(reference)
        assert after_[parent].link_tx - before[parent].link_tx >= wire_bytes(reference)
      end

      # A PNG job's pixels travel as compressed 8-bit sRGB: at most 3.5
      # bytes a pixel come in on the parent's link, headers included.
      before = Lab.counters(lab)

      png_job = [
        nodes: lab.workers,
        local: false,
        children_per_node: 2,
        atoms: 4,
        width: 96,
        height: 72,
        pixels: :srgb8
      ]

      {:ok, r} = Lab.call(lab.parent, Remote, :render, [scene, png_job, 2, true])
      after_ = Lab.counters(lab)
      assert r.pixels == RingTracer.Image.srgb8(reference)
      parent = lab.parent.name
      assert (after_[parent].link_tx - before[parent].link_tx) / (96 * 72) <= 3.5

      # The rate changes on both ends of every link.
      lab = Lab.set_rate(lab, "1gbit")

      for n <- lab.nodes do
        {hub, 0} = System.cmd("tc", ~w(-n #{lab.hub} qdisc show dev h#{n.index}))
        {own, 0} = System.cmd("tc", ~w(-n #{n.ns} qdisc show dev eth0))
        assert hub =~ "1Gbit" and own =~ "1Gbit"
      end

      namespaces
    end)
    |> then(fn namespaces ->
      # Everything is gone afterwards.
      {listed, 0} = System.cmd("ip", ["netns", "list"])
      for ns <- namespaces, do: refute(listed =~ ns)
    end)
  end

  # The bytes of the job's atoms (4 children x 4 atoms) as they travel:
  # each one's pixels, encoded.
  defp wire_bytes(reference) do
    layout = RingTracer.Layout.new(96, 72, 4, 4)

    layout
    |> RingTracer.Layout.atoms()
    |> Enum.map(fn a ->
      {first, count} = RingTracer.Layout.span(layout, a)
      slice = RingTracer.Pixels.slice(reference, :float, first, count)
      {:ok, wire} = RingTracer.Pixels.encode(slice, :float)
      byte_size(wire)
    end)
    |> Enum.sum()
  end

  test "a lab whose work fails is removed all the same" do
    parent = self()

    assert_raise RuntimeError, "on purpose", fn ->
      Lab.with_lab([workers: 1], fn lab ->
        send(parent, {:namespaces, [lab.hub | Enum.map(lab.nodes, & &1.ns)]})
        raise "on purpose"
      end)
    end

    assert_received {:namespaces, namespaces}
    {listed, 0} = System.cmd("ip", ["netns", "list"])
    for ns <- namespaces, do: refute(listed =~ ns)
  end
end

defmodule RingTracer.Bench.NetworkPureTest do
  # The parts that need no namespaces: in every run of the suite.
  use ExUnit.Case, async: true

  alias RingTracer.Bench.Network

  doctest RingTracer.Bench.Network.Lab

  test "the job's options put the children on the workers with their speeds" do
    job =
      Network.job(workers: 2, children: 2, atoms: 8, size: 64, speeds: "1,1,4,1", pixels: "srgb8")

    assert job[:children] == 4 and job[:speeds] == [1, 1, 4, 1]
    assert job[:pixels] == :srgb8

    three =
      Network.job(workers: 3, children: 1, atoms: 8, size: 64, speeds: "1,2", pixels: "float")

    assert three[:speeds] == [1, 2, 1]
    assert three[:pixels] == :float

    assert_raise ArgumentError, ~r/--pixels: srgb8 or float/, fn ->
      Network.job(workers: 1, children: 1, atoms: 1, size: 8, speeds: "1", pixels: "f16")
    end
  end
end
