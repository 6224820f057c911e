defmodule RingTracer.Preview.BrowserTest do
  # Debian's chromium, headless, watches a slowed render through the preview:
  # a screenshot part-way and one at the end, and at the end the canvas's
  # pixels (the page puts canvas.toDataURL() in #result, read back with
  # --dump-dom) must equal the PNG the job wrote, and the lanes must name
  # every child. Installs chromium with apt-get when missing; without it the
  # test says so and checks nothing.
  use ExUnit.Case, async: false
  # `bin/ringtracer test` runs it in a second test VM (docs/testing.md).
  @moduletag :second_vm

  alias RingTracer.Test.{CDP, PNG}

  @moduletag :browser
  @moduletag timeout: 240_000
  @children 3

  setup_all do
    {:ok, chromium: chromium()}
  end

  defp chromium do
    case System.find_executable("chromium") do
      nil ->
        if System.find_executable("apt-get") do
          System.cmd("apt-get", ["install", "-y", "-qq", "chromium"],
            env: [{"DEBIAN_FRONTEND", "noninteractive"}],
            stderr_to_stdout: true
          )
        end

        System.find_executable("chromium")

      path ->
        path
    end
  end

  @tag :tmp_dir
  test "a browser sees the image fill in, every child's lane, and at the end the job's PNG",
       %{chromium: chromium, tmp_dir: dir} do
    if chromium == nil do
      IO.puts(:stderr, "\nskipped: chromium is not installed and apt-get could not install it")
    else
      run(chromium, dir)
    end
  end

  defp run(chromium, dir) do
    {:ok, preview} = RingTracer.Preview.start()

    try do
      # One browser, on the page before the job starts, until its end.
      cdp = CDP.start(chromium, preview.url, Path.join(dir, "profile"))

      assert RingTracer.Test.Wait.eventually(
               fn -> RingTracer.Preview.viewers(preview) == 1 end,
               3000
             )

      job =
        Task.async(fn ->
          RingTracer.render("priv/scenes/balls_s1.nff",
            width: 320,
            height: 240,
            children: @children,
            atoms: 8,
            speeds: [600, 800, 600],
            preview: preview
          )
        end)

      # Part-way: a third of the atoms or more on the canvas, not all.
      total = @children * 8

      cdp =
        CDP.await(
          cdp,
          "document.body.dataset.state === 'running' && " <>
            "+document.getElementById('atoms').textContent.split(' / ')[0] >= #{div(total, 3)}",
          180_000
        )

      {partway, cdp} = CDP.screenshot(cdp)
      {shown, cdp} = CDP.eval(cdp, "document.getElementById('atoms').textContent")
      [done_then, ^total] = shown |> String.split(" / ") |> Enum.map(&String.to_integer/1)
      assert done_then > 0 and done_then < total

      {:ok, result} = Task.await(job, 200_000)
      cdp = CDP.await(cdp, "document.body.dataset.state === 'done'")
      # The final screenshot with the atom outlines on (they do not touch the image's canvas).
      {_, cdp} = CDP.eval(cdp, "document.getElementById('outlines').click()")
      {final, cdp} = CDP.screenshot(cdp)
      {data_url, cdp} = CDP.eval(cdp, "document.getElementById('result').textContent")

      {lanes, cdp} =
        CDP.eval(cdp, "[...document.querySelectorAll('.lane-label')].map(e => e.textContent)")

      CDP.stop(cdp)

      for shot <- [partway, final], do: assert(<<0x89, "PNG", _::binary>> = shot)

      if out = System.get_env("PREVIEW_SCREENSHOTS") do
        File.write!(Path.join(out, "preview-partway.png"), partway)
        File.write!(Path.join(out, "preview-final.png"), final)
      end

      # The canvas, read back as PNG, is the job's image, pixel for pixel.
      "data:image/png;base64," <> b64 = data_url
      {w, h, 4, canvas} = PNG.decode(Base.decode64!(b64))
      {:ok, png} = RingTracer.Image.to_png(result)
      {^w, ^h, 3, job_pixels} = PNG.decode(png)
      assert {w, h} == {320, 240}
      assert for(<<_r, _g, _b, a <- canvas>>, uniq: true, do: a) == [255]
      assert rgb(canvas) == job_pixels

      # A lane per child, each naming its node.
      assert length(lanes) == @children

      for {label, i} <- Enum.with_index(lanes),
          do: assert(label =~ "child #{i} · #{node()}")
    after
      RingTracer.Preview.stop(preview)
    end
  end

  @tag :tmp_dir
  test "a browser sees a sequence: the images in flight, a bounded strip of finished frames with their times, and the last frame",
       %{chromium: chromium, tmp_dir: dir} do
    if chromium == nil do
      IO.puts(:stderr, "\nskipped: chromium is not installed and apt-get could not install it")
    else
      run_sequence(chromium, dir)
    end
  end

  defp run_sequence(chromium, dir) do
    # A strip of 3 thumbnails, for a sequence of 30 frames.
    {:ok, preview} = RingTracer.Preview.start(strip: 3)

    try do
      cdp = CDP.start(chromium, preview.url, Path.join(dir, "profile"))

      assert RingTracer.Test.Wait.eventually(
               fn -> RingTracer.Preview.viewers(preview) == 1 end,
               3000
             )

      {:ok, job} =
        RingTracer.render_sequence("priv/scenes/whitted_orbit.toml",
          frames: 1..30,
          width: 16,
          height: 12,
          children: 2,
          speeds: [50, 50],
          preview: preview,
          # 8 bits, as `ringtracer render` sends frames written as PNGs
          pixels: :srgb8
        )

      id = job.id
      # Part-way: the children held once the first frame is done and a later
      # one is in flight, and the page caught up with the preview's log
      # (nothing comes meanwhile).
      assert_receive {RingTracer, ^id, {:frame, _, first}}, 60_000
      {holder, showing, cdp} = held_in_flight(cdp, preview, id, 20)

      # The frames in flight, the oldest shown, labelled with its number,
      # and the frames finished in the strip.
      assert showing =~ ~r"\Aframe \d+, the oldest in flight: \d+ / 32 atoms\z"
      {chips, cdp} = CDP.eval(cdp, "document.querySelectorAll('#inflight .chip').length")
      assert chips > 0
      {thumbs, cdp} = CDP.eval(cdp, "document.querySelectorAll('#strip .thumb').length")
      assert thumbs > 0
      {state, cdp} = CDP.eval(cdp, "document.body.dataset.state")
      assert state == "running"

      {hidden, cdp} = CDP.eval(cdp, "document.getElementById('sequence').hidden")
      assert hidden == false
      {partway, cdp} = CDP.screenshot(cdp)
      send(holder, :release)

      frames = collect(id, %{first.number => first})
      assert Map.keys(frames) |> Enum.sort() == Enum.to_list(1..30)

      cdp = CDP.await(cdp, "document.body.dataset.state === 'done'")
      {final, cdp} = CDP.screenshot(cdp)

      {strip, cdp} =
        CDP.eval(
          cdp,
          "[...document.querySelectorAll('#strip .thumb')].map(e => [+e.dataset.n, +e.dataset.us, e.textContent])"
        )

      {done, cdp} = CDP.eval(cdp, "document.getElementById('framesdone').textContent")
      {time, cdp} = CDP.eval(cdp, "document.getElementById('frametime').textContent")
      {data_url, cdp} = CDP.eval(cdp, "document.getElementById('result').textContent")
      CDP.stop(cdp)

      if out = System.get_env("PREVIEW_SCREENSHOTS") do
        File.write!(Path.join(out, "preview-sequence-partway.png"), partway)
        File.write!(Path.join(out, "preview-sequence.png"), final)
      end

      # The strip: the last 3 frames, in order, each with its own time.
      assert Enum.map(strip, &hd/1) == [28, 29, 30]

      for [n, us, caption] <- strip do
        assert us == RingTracer.Frame.elapsed_us(frames[n])
        assert caption =~ ~r/\A#{n} · \d+\.\d (ms|s)\z/
      end

      assert done == "30 / 30 complete"
      assert time =~ "mean "

      # At the end the page shows the last frame, pixel for pixel.
      "data:image/png;base64," <> b64 = data_url
      {16, 12, 4, canvas} = PNG.decode(Base.decode64!(b64))
      assert frames[30].pixel_format == :srgb8
      assert rgb(canvas) == frames[30].pixels
    after
      RingTracer.Preview.stop(preview)
    end
  end

  # The children held, the page caught up, and what it shows as the oldest
  # frame in flight. Held just as a frame completes, before an atom of the
  # next has come, no frame is in flight (the page shows none): then the
  # children go on until the next progress, and are held again.
  defp held_in_flight(cdp, preview, id, tries) do
    holder = hold_children()

    assert RingTracer.Test.Wait.eventually(fn ->
             state = :sys.get_state(preview.pid)
             :queue.is_empty(state.queue) and state.pacing == nil
           end)

    seq = :sys.get_state(preview.pid).log.seq
    cdp = CDP.await(cdp, "document.body.dataset.seq === '#{seq}'", 30_000)
    {showing, cdp} = CDP.eval(cdp, "document.getElementById('showing').textContent")

    if showing == "" and tries > 0 do
      send(holder, :release)
      # an atom that comes after the release: the ones before are drained
      drain_progress(id)
      assert_receive {RingTracer, ^id, {:progress, _, _}}, 60_000
      held_in_flight(cdp, preview, id, tries - 1)
    else
      {holder, showing, cdp}
    end
  end

  defp drain_progress(id) do
    receive do
      {RingTracer, ^id, {:progress, _, _}} -> drain_progress(id)
    after
      0 -> :ok
    end
  end

  # Suspends this node's render children until the process returned is
  # sent :release (a suspension ends with the process that made it).
  defp hold_children do
    me = self()

    holder =
      spawn(fn ->
        for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Children),
            is_pid(pid),
            do: :erlang.suspend_process(pid)

        send(me, :held)

        receive do
          :release -> :ok
        end
      end)

    assert_receive :held, 10_000
    holder
  end

  defp collect(id, frames) do
    receive do
      {RingTracer, ^id, {:frame, n, frame}} -> collect(id, Map.put(frames, n, frame))
      {RingTracer, ^id, {:progress, _, _}} -> collect(id, frames)
      {RingTracer, ^id, {:ok, _}} -> frames
      {RingTracer, ^id, {:error, error}} -> flunk(inspect(error))
    after
      120_000 -> flunk("the sequence did not end")
    end
  end

  defp rgb(rgba), do: for(<<r, g, b, _a <- rgba>>, into: <<>>, do: <<r, g, b>>)
end
