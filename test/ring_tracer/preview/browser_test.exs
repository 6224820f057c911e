defmodule RingTracer.Preview.BrowserTest do
  # Debian's chromium, headless, watches a slowed render through the preview:
  # a screenshot part-way and one at the end, and at the end the canvas's
  # pixels (the page puts canvas.toDataURL() in #result, read back with
  # --dump-dom) must equal the PNG the job wrote, and the lanes must name
  # every child. Installs chromium with apt-get when missing; without it the
  # test says so and checks nothing.
  use ExUnit.Case, async: false

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

  defp rgb(rgba), do: for(<<r, g, b, _a <- rgba>>, into: <<>>, do: <<r, g, b>>)
end
