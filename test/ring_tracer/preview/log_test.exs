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

  test "a job in 8 bits: its atoms and thumbnails are the same texts as of the floats" do
    for n <- [1, 4096, 4097, 10_001] do
      floats =
        for i <- 1..(3 * n), into: <<>>, do: <<rem(i * 7919, 1201) / 1000::float-32-native>>

      eight = RingTracer.Image.srgb8(floats)

      texts =
        for {px, format} <- [{floats, :float}, {eight, :srgb8}] do
          log = Log.job(Log.new(), Map.put(info(), :format, format))
          {_, log} = Log.take(log)
          [{_, "atom", a}] = frames(Log.atom(log, 0, 0, px, 1, 1, nil))
          a["px"]
        end

      assert [text, text] = texts
      assert text == Base.encode64(eight)
    end

    floats = for i <- 1..(3 * 200 * 100), into: <<>>, do: <<rem(i, 97) / 97::float-32-native>>
    eight = RingTracer.Image.srgb8(floats)

    assert Log.thumbnail(%{width: 200, height: 100, pixels: eight, pixel_format: :srgb8}) ==
             Log.thumbnail(%{width: 200, height: 100, pixels: floats})

    assert {4, 2, nil} =
             Log.thumbnail(%{width: 4, height: 2, pixels: eight, pixel_format: :srgb8})
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

  describe "a sequence" do
    # 2 children, 2 atoms each: 4 atoms an image, of 4x2 pixels.
    defp seq_info(frames, opts \\ []) do
      %{
        info()
        | layout: Layout.new(4, 2, 2, 2) |> Layout.with_frames(frames),
          results: Keyword.get(opts, :results, %{}),
          traced_by: Keyword.get(opts, :traced_by, %{})
      }
      |> Map.put(:from_start, Keyword.get(opts, :from_start, true))
    end

    defp image(n, elapsed, px \\ nil),
      do: %{number: n, width: 4, height: 2, pixels: px, at_us: 1000 * n, elapsed_us: elapsed}

    # What a viewer can still read: the log's frames less those forgotten.
    defp store(log, table \\ %{}) do
      {frames, log} = Log.take(log)
      {forget, log} = Log.forget(log)
      table = Map.drop(Map.merge(table, Map.new(frames)), forget)
      {log, table}
    end

    defp decoded(table) do
      for {seq, f} <- Enum.sort(table) do
        [_, name, json] = Regex.run(~r/\Aevent: (\w+)\ndata: (.*)\n\n\z/s, f)
        {seq, name, :jiffy.decode(json, [:return_maps, :use_nil])}
      end
    end

    # Image `f` (from 0) released as frame number f + 1, all its atoms, and
    # it complete, the last atom before it.
    defp run_image(log, f, elapsed) do
      log = Log.release(log, f + 1, 100 * f)

      log =
        Enum.reduce(Layout.frame_atoms(log_layout(), f), log, fn a, l ->
          Log.atom(l, a, rem(a, 2), pixels(2, f / 100), 1, 1, 1_000_000 + a)
        end)

      Log.image_done(log, f * 4 + 3, image(f + 1, elapsed, pixels(8, f / 100)))
    end

    defp log_layout, do: Layout.new(4, 2, 2, 2) |> Layout.with_frames(1000)

    test "the job frame describes one image's atoms, and the images" do
      [{1, "job", job}] = frames(Log.job(Log.new(), seq_info(10)))
      assert job["total"] == 40 and job["m"] == 4 and job["frames"] == 10
      assert job["owners"] == [0, 0, 1, 1]
      assert job["spans"] == [[0, 2], [2, 2], [4, 2], [6, 2]]
      assert job["strip"] == 12
    end

    test "images released and complete: their indices, numbers, times and thumbnails" do
      {log, _} = Log.new() |> Log.job(seq_info(3)) |> store()
      log = Log.release(log, 7, 50) |> Log.release(8, 60)
      log = Log.atom(log, 4, 1, pixels(2, 1.0), 3, 2, 1_000_070)
      log = Log.atom(log, 1, 0, pixels(2, 0.0), 3, 2, 1_000_080)

      assert [
               {2, "release", %{"f" => 0, "n" => 7, "at" => 50}},
               {3, "release", %{"f" => 1, "n" => 8, "at" => 60}},
               {4, "atom", %{"a" => 4, "c" => 1}},
               {5, "atom", %{"a" => 1, "c" => 0}}
             ] = frames(log)

      {_, log} = Log.take(log)
      white = pixels(8, 1.0)
      log = Log.image_done(log, 1, image(7, 3000, white))
      [{6, "frame", f}] = frames(log)

      assert Map.delete(f, "px") == %{
               "f" => 0,
               "n" => 7,
               "at" => 7000,
               "us" => 3000,
               "completed" => 1,
               "mean_us" => 3000,
               "tw" => 4,
               "th" => 2,
               "flight" => [1]
             }

      assert Base.decode64!(f["px"]) == :binary.copy(<<255>>, 24)

      {_, log} = Log.take(log)
      log = Log.image_done(log, 4, image(8, 1000))
      [{7, "frame", g}] = frames(log)
      assert {g["f"], g["completed"], g["mean_us"], g["px"], g["flight"]} == {1, 2, 2000, nil, []}
    end

    test "what a viewer can read stays bounded: images in flight, one complete, the strip" do
      {log, table} = Log.new(strip: 3) |> Log.job(seq_info(1000)) |> store()

      {log, table} =
        Enum.reduce(0..199, {log, table}, fn f, {l, t} ->
          l |> run_image(f, 10 * f) |> store(t)
        end)

      # In flight: image 200 released, one atom of it.
      {log, table} =
        log
        |> Log.release(201, 0)
        |> Log.atom(800, 0, pixels(2, 0.5), 1, 1, 1_000_000)
        |> store(table)

      names = decoded(table) |> Enum.map(fn {_, name, d} -> {name, d["n"] || d["a"]} end)

      assert names == [
               {"job", nil},
               # the strip: the last 3 complete
               {"frame", 198},
               {"frame", 199},
               # the highest image complete: its release and atoms, for the page
               # to show when none is in flight
               {"release", 200},
               {"atom", 796},
               {"atom", 797},
               {"atom", 798},
               {"atom", 799},
               {"frame", 200},
               # in flight
               {"release", 201},
               {"atom", 800}
             ]

      [last] = for {_, "frame", %{"n" => 200} = d} <- decoded(table), do: d
      assert last["completed"] == 200
      assert last["mean_us"] == div(Enum.sum(for f <- 0..199, do: 10 * f), 200)
      # Atoms of images complete are forgotten by the log too.
      assert MapSet.size(log.atoms) == 1
      assert map_size(log.flight) == 1
    end

    test "images complete out of order: the strip and the image shown keep the highest numbers" do
      {log, table} = Log.new(strip: 2) |> Log.job(seq_info(1000)) |> store()

      {log, table} =
        Enum.reduce(0..3, {log, table}, fn f, {l, t} ->
          Log.release(l, f + 1, 0)
          |> then(
            &Enum.reduce(Layout.frame_atoms(log_layout(), f), &1, fn a, l2 ->
              Log.atom(l2, a, 0, pixels(2, 0.1), 1, 1, 1_000_000)
            end)
          )
          |> store(t)
        end)

      # Complete in the order 4, 1, 3, 2.
      {_log, table} =
        Enum.reduce([3, 0, 2, 1], {log, table}, fn f, {l, t} ->
          l |> Log.image_done(f * 4 + 3, image(f + 1, 10)) |> store(t)
        end)

      # The strip (4 and 3), and the newest frame, the last to complete: a page
      # that lagged past the others learns from it that all 4 are complete and
      # none is in flight.
      frames = for {_, "frame", d} <- decoded(table), do: d
      assert Enum.map(frames, & &1["n"]) == [4, 3, 2]
      assert %{"completed" => 4, "flight" => []} = List.last(frames)
      assert for({_, "atom", d} <- decoded(table), do: d["a"]) == [12, 13, 14, 15]
      assert for({_, "release", d} <- decoded(table), do: d["n"]) == [4]
    end

    test "opened on a running sequence: images already complete are counted, indices unknown" do
      info =
        seq_info(10,
          from_start: false,
          results: %{9 => pixels(2, 0.5)},
          traced_by: %{9 => 1, 13 => 0}
        )

      {log, table} = Log.new() |> Log.job(info) |> store()
      assert log.completed == 2
      {log, table} = log |> Log.release(5, 10) |> store(table)

      assert [
               {1, "job", _},
               {2, "atom", %{"a" => 9, "at" => nil}},
               {3, "release", %{"f" => nil, "n" => 5, "at" => 10}}
             ] = decoded(table)

      # Images 4, 5 and 6 complete (the last with no atom before it): the
      # count goes on from 2, the mean is of those seen, and the releases of
      # images of an unknown index are forgotten by their numbers...
      {log, table} = log |> Log.image_done(13, image(4, 100)) |> store(table)

      {log, table} =
        log
        |> Log.release(6, 20)
        |> Log.image_done(16, image(5, 300))
        |> Log.image_done(nil, image(6, 500))
        |> store(table)

      frames =
        for {_, "frame", f} <- decoded(table), do: {f["f"], f["n"], f["completed"], f["mean_us"]}

      assert frames == [{3, 4, 3, 100}, {4, 5, 4, 200}, {nil, 6, 5, 300}]
      # (but that of the image shown at the end, the highest complete)
      assert for({_, "release", r} <- decoded(table), do: r["n"]) == [6]
      assert log.unindexed == %{}
    end

    test "hand-overs count with the events against the bound" do
      {log, _} = Log.new(max_events: 2) |> Log.job(seq_info(3)) |> store()

      log =
        log
        |> Log.event(:offer, 0, 1, 5)
        |> Log.move(:parent, 1, 2, 1_000_400)
        |> Log.move(0, 1, 1, 1_000_500)

      assert [{2, "ev", _}, {3, "move", _}] = frames(log)
      assert log.dropped == 1
    end

    test "a thumbnail is the image's nearest pixels, at most 96 a side" do
      # 200x100: pixel (x, y) has red x / 1000, green y / 1000.
      px =
        for y <- 0..99,
            x <- 0..199,
            into: <<>>,
            do: <<x / 1000::float-32-native, y / 1000::float-32-native, 0.0::float-32-native>>

      {tw, th, b64} = Log.thumbnail(%{width: 200, height: 100, pixels: px})
      assert {tw, th} == {96, 48}
      thumb = Base.decode64!(b64)
      assert byte_size(thumb) == 96 * 48 * 3
      # Thumbnail pixel (tx, ty) is image pixel (⌊(2tx+1)·200/192⌋, ⌊(2ty+1)·100/96⌋).
      for {tx, ty} <- [{0, 0}, {95, 47}, {40, 20}] do
        {x, y} = {div((2 * tx + 1) * 200, 192), div((2 * ty + 1) * 100, 96)}
        expected = RingTracer.Image.srgb8(binary_part(px, (y * 200 + x) * 12, 12))
        assert binary_part(thumb, (ty * 96 + tx) * 3, 3) == expected
      end

      small = pixels(8, 0.25)

      assert Log.thumbnail(%{width: 4, height: 2, pixels: small}) ==
               {4, 2, Base.encode64(RingTracer.Image.srgb8(small))}

      assert Log.thumbnail(%{width: 4, height: 2, pixels: nil}) == {4, 2, nil}
    end

    test "the final frame has the atoms and events of the strip's images, and the images' mean time" do
      {log, _} = Log.new(strip: 2) |> Log.job(seq_info(5)) |> store()

      atoms =
        for a <- 0..19,
            do: %{atom: a, owner: 0, child: 0, start_us: 100 * a, end_us: 100 * a + 50}

      raw = %{
        elapsed_us: 3000,
        teardown_us: 5,
        duplicates: 0,
        redone: 0,
        traffic: %{},
        children: [],
        atoms: atoms,
        events: for(t <- [100, 1150, 1300, 1900], do: %{kind: :offer, from: 0, to: 1, at_us: t}),
        frames:
          for(
            n <- 1..5,
            do: %RingTracer.Frame{
              number: n,
              width: 4,
              height: 2,
              pixels: nil,
              released_us: 0,
              completed_us: 100 * n
            }
          )
      }

      [{_, "final", f}, {_, "end", _}] = frames(Log.final(log, {:ok, raw}))
      # The last 2 images of 5: atoms 12 to 19.
      assert Enum.map(f["atoms"], & &1["atom"]) == Enum.to_list(12..19)
      assert Enum.map(f["events"], & &1["at_us"]) == [1300, 1900]
      assert {f["frames"], f["mean_us"]} == {5, 300}
    end
  end
end
