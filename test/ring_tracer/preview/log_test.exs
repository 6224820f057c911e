defmodule RingTracer.Preview.LogTest do
  use ExUnit.Case, async: true

  alias RingTracer.Layout
  alias RingTracer.Preview.Log

  defp info(results \\ %{}, traced_by \\ %{}) do
    %{
      id: make_ref(),
      t0: 1_000_000,
      layout: Layout.new(4, 3, 2, 3),
      strategy: RingTracer.Strategy.Ring,
      nodes: [node(), node()],
      speeds: [1, 4],
      results: results,
      traced_by: traced_by
    }
  end

  # One linear-float pixel per 12 bytes.
  defp pixels(n, v),
    do: :binary.copy(<<v::float-32-native, v::float-32-native, v::float-32-native>>, n)

  defp frames(log) do
    {frames, _} = Log.take(log)

    for {seq, f} <- frames do
      [_, name, json] = Regex.run(~r/\Aevent: (\w+)\ndata: (.*)\n\n\z/s, f)
      {seq, name, :jiffy.decode(json, [:return_maps, :use_nil])}
    end
  end

  test "the job frame describes the layout: owners, spans, palette, nodes" do
    [{1, "job", job}] = frames(Log.job(Log.new(), info()))

    assert job["width"] == 4 and job["height"] == 3 and job["children"] == 2
    assert job["total"] == 6
    assert job["owners"] == [0, 0, 0, 1, 1, 1]
    assert job["spans"] == [[0, 2], [2, 2], [4, 2], [6, 2], [8, 2], [10, 2]]
    assert job["palette"] == [RingTracer.Report.Palette.hex(0), RingTracer.Report.Palette.hex(1)]
    assert job["speeds"] == [1, 4]
    assert job["nodes"] == [Atom.to_string(node()), Atom.to_string(node())]
  end

  test "an atom becomes one frame of 8-bit sRGB pixels, and its second copy none" do
    log = Log.job(Log.new(), info())
    {_, log} = Log.take(log)
    log = Log.atom(log, 3, 1, pixels(2, 1.0), 50, 7, 1_000_250)
    log = Log.atom(log, 3, 0, pixels(2, 0.0), 50, 7, 1_000_300)

    assert [{2, "atom", a}] = frames(log)
    assert a["a"] == 3 and a["c"] == 1 and a["rays"] == 50 and a["tus"] == 7
    assert a["at"] == 250
    assert Base.decode64!(a["px"]) == RingTracer.Image.srgb8(pixels(2, 1.0))
    assert Base.decode64!(a["px"]) == <<255, 255, 255, 255, 255, 255>>
  end

  test "an atom's pixels are encoded piece by piece into one base64 text, any size" do
    for n <- [1, 2, 3, 4095, 4096, 4097, 8192, 10_001] do
      # Values across the range, out of it too, and not numbers.
      floats = for i <- 1..(3 * n), do: rem(i * 7919, 1201) / 1000 - 0.1
      px = for(v <- floats, into: <<>>, do: <<v::float-32-native>>)

      px =
        if n > 4,
          do:
            <<0x7FC00000::32-native, 0xFF800000::32-native>> <>
              binary_part(px, 8, byte_size(px) - 8),
          else: px

      log = Log.job(Log.new(), info())
      {_, log} = Log.take(log)
      [{_, "atom", a}] = frames(Log.atom(log, 0, 0, px, 1, 1, nil))
      assert a["px"] == Base.encode64(RingTracer.Image.srgb8(px)), "#{n} pixels"
    end
  end

  test "a late joiner's log starts with the atoms traced before it opened, in order" do
    results = %{4 => pixels(2, 0.5), 1 => pixels(2, 0.25)}
    log = Log.job(Log.new(), info(results, %{4 => 1, 1 => 0}))

    assert [{1, "job", _}, {2, "atom", a1}, {3, "atom", a4}] = frames(log)
    assert {a1["a"], a1["c"], a1["at"]} == {1, 0, nil}
    assert {a4["a"], a4["c"]} == {4, 1}
    # ...and a copy arriving afterwards is not drawn twice.
    {_, log} = Log.take(log)
    assert frames(Log.atom(log, 4, 1, pixels(2, 0.5), 1, 1, 1_000_001)) == []
  end

  test "protocol events are kept up to the bound, then only counted" do
    log = Log.new(max_events: 2) |> Log.job(info())
    {_, log} = Log.take(log)

    log =
      Enum.reduce(1..5, log, fn i, l -> Log.event(l, :offer, 0, 1, i) end)
      |> Log.move(:parent, 1, 2, 1_000_400)

    assert [{2, "ev", e1}, {3, "ev", _}, {4, "move", m}] = frames(log)
    assert e1 == %{"kind" => "offer", "from" => 0, "to" => 1, "at" => 1}
    assert m == %{"from" => "parent", "to" => 1, "n" => 2, "at" => 400}
    assert log.dropped == 3
  end

  test "the final frame carries the statistics, then the end; nothing comes after" do
    {:ok, result} =
      RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 6, children: 2, atoms: 2)

    raw = %{
      elapsed_us: result.elapsed_us,
      teardown_us: 5,
      duplicates: 0,
      redone: 0,
      traffic: %{result: {4, 1000}},
      children: result.children,
      atoms: result.atoms,
      events: [%{kind: :offer, from: 0, to: 1, at_us: 10}]
    }

    log = Log.new() |> Log.job(info())
    {_, log} = Log.take(log)
    log = Log.final(log, {:ok, raw})

    assert [{2, "final", f}, {3, "end", %{}}] = frames(log)
    assert f["ok"] == true
    assert f["traffic"] == %{"result" => %{"n" => 4, "bytes" => 1000}}
    assert length(f["children"]) == 2
    assert Enum.map(f["children"], & &1["traced"]) == Enum.map(result.children, & &1.traced)
    assert length(f["atoms"]) == 4
    assert f["events"] == [%{"kind" => "offer", "from" => 0, "to" => 1, "at_us" => 10}]

    {_, log} = Log.take(log)
    log = log |> Log.atom(0, 0, pixels(2, 1.0), 1, 1, 1) |> Log.gone(:killed)
    assert frames(log) == []
  end

  test "a job that failed or went away ends its log with the reason" do
    log = Log.new() |> Log.job(info())
    {_, log} = Log.take(log)

    assert [{2, "final", %{"ok" => false, "error" => "atom 3 failed"}}, {3, "end", _}] =
             frames(Log.final(log, {:error, "atom 3 failed"}))

    assert [{2, "final", %{"ok" => false, "error" => "the job ended: :killed"}}, _] =
             frames(Log.gone(log, :killed))
  end
end
