defmodule RingTracer.CLI.RenderTest do
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO
  alias RingTracer.CLI.Render

  @moduletag :tmp_dir

  defp render(args) do
    me = self()

    out =
      capture_io(fn -> capture_io(:stderr, fn -> send(me, {:r, Render.execute(args)}) end) end)

    assert_received {:r, result}
    {result, out}
  end

  test "--region in pixels or fractions gives that part", %{tmp_dir: dir} do
    {:ok, out} =
      render(
        ~w(priv/scenes/balls_s2.nff -o #{dir}/a.png --width 64 --region 10,5,40,30 -q --progress none)
      )

    assert out == ""
    assert File.exists?(Path.join(dir, "a.png"))

    {:ok, out} =
      render(
        ~w(priv/scenes/balls_s2.nff -o #{dir}/b.png --width 64 --region 0.5,0,1,0.25 --progress none)
      )

    assert out =~ "b.png (32x16)"

    assert {{:error, 2, message}, _} =
             render(~w(priv/scenes/balls_s2.nff -o #{dir}/c.png --region 1,2,3))

    assert message =~ "--region takes X0,Y0,X1,Y1"
  end

  test "values out of range and bad choices are usage errors that say what is accepted", %{
    tmp_dir: dir
  } do
    for {args, text} <- [
          {~w(--samples 17), "--samples takes an integer from 1 to 16, got: 17"},
          {~w(--strategy ringg), "--strategy takes one of"},
          {~w(--speeds 1,0.5), "--speeds takes numbers from 1 to 1000"},
          {~w(--speeds 1,,1), "--speeds takes numbers from 1 to 1000"},
          # refused by the render itself, before any work: still usage errors, in the CLI's words
          {~w(--children 2 --atoms 1048576), "--children x --atoms must be at most 1048576"},
          {~w(--region 10,10,5000,5000), "is not inside the"},
          {~w(--cutoff -1), "--cutoff takes a number from 0"},
          {~w(--progress loud), "--progress takes bar, log or none"}
        ] do
      assert {{:error, 2, message}, _} =
               render(~w(priv/scenes/balls_s2.nff -o #{dir}/x.png) ++ args)

      assert message =~ text
    end

    refute File.exists?(Path.join(dir, "x.png"))
  end

  test "--frame renders that frame of an animated scene; past the last it is a usage error", %{
    tmp_dir: dir
  } do
    scene = "priv/scenes/whitted_orbit.toml"
    args = ~w(--width 32 --children 2 -q --progress none)
    {:ok, ""} = render(~w(#{scene} -o #{dir}/f1.png) ++ args)
    {:ok, ""} = render(~w(#{scene} -o #{dir}/f7.png --frame 7) ++ args)
    assert File.read!(Path.join(dir, "f1.png")) != File.read!(Path.join(dir, "f7.png"))

    assert {{:error, 2, message}, _} = render(~w(#{scene} -o #{dir}/f0.png --frame 0) ++ args)
    assert message =~ "--frame takes an integer from 1"

    assert {{:error, 2, message}, _} = render(~w(#{scene} -o #{dir}/f49.png --frame 49) ++ args)
    assert message =~ "frame must be at most 48 (the frames of whitted_orbit.toml), got: 49"
    refute File.exists?(Path.join(dir, "f49.png"))
  end

  describe "sequences" do
    @scene "priv/scenes/whitted_orbit.toml"
    @tiny ~w(--width 16 --height 12 --children 2 --atoms 2 --progress none)

    test "their options are checked, naming them, before any work", %{tmp_dir: dir} do
      pattern = Path.join(dir, "f_##.png")

      for {args, text} <- [
            {~w(-o #{pattern} --frames 40-60),
             "--frames 40-60: whitted_orbit.toml has 48 frames (1 to 48)"},
            {~w(-o #{pattern} --frames 0-2), "--frames takes A-B"},
            {~w(-o #{pattern} --frame 2 --frames 1-3), "not both"},
            {~w(-o #{dir}/f.png --frames 1-3),
             "--out #{dir}/f.png: a sequence of 3 frames needs a run of #"},
            {~w(-o #{dir}/f_#_#.png), "--out #{dir}/f_#_#.png: one run of #"},
            {~w(-o #{pattern} --ownership #{dir}/o.png), "--ownership tints one frame's image"},
            {~w(-o #{pattern} --frames 1-2 --region 0,0,4,4),
             "--region traces part of one frame"},
            {~w(-o #{pattern} --frames 1-2 --aim), "--aim aims a ring's offers within one image"},
            {~w(-o #{pattern} --window 0), "--window takes an integer from 1 to 64"},
            {~w(-o #{dir}/f_#.jpg), "--out #{dir}/f_#.jpg: the image must end in .png or .exr"}
          ] do
        assert {{:error, 2, message}, _} = render([@scene | args] ++ @tiny)
        assert message =~ text
      end

      assert File.ls!(dir) == []
    end

    test "a frame path that is a folder is refused before any work", %{tmp_dir: dir} do
      File.mkdir!(Path.join(dir, "f_03.png"))

      assert {{:error, 2, message}, _} =
               render([@scene | ~w(-o #{dir}/f_##.png --frames 1-4)] ++ @tiny)

      assert message =~ "--out #{dir}/f_03.png: exists and is a directory"
      assert File.ls!(dir) == ["f_03.png"]
    end

    test "--frame F with a # in --out writes frame F's file, the same as without", %{
      tmp_dir: dir
    } do
      {:ok, out} = render([@scene | ~w(-o #{dir}/f_###.png --frame 7)] ++ @tiny)
      assert out =~ "wrote #{dir}/f_007.png (16x12)"
      {:ok, _} = render([@scene | ~w(-o #{dir}/plain.png --frame 7 -q)] ++ @tiny)
      assert File.read!(Path.join(dir, "f_007.png")) == File.read!(Path.join(dir, "plain.png"))
    end

    test "--continue: with every frame there it renders nothing and says so", %{tmp_dir: dir} do
      for n <- 1..3, do: :ok = RingTracer.Output.write(Path.join(dir, "f_0#{n}.png"), "whole")

      assert {:ok, out} =
               render([@scene | ~w(-o #{dir}/f_##.png --frames 1-3 --continue)] ++ @tiny)

      assert out == "--continue: all 3 frames are already written; nothing to render\n"

      assert {:ok, out} = render([@scene | ~w(-o #{dir}/f_##.png --frame 2 --continue)] ++ @tiny)
      assert out == "--continue: #{dir}/f_02.png is already written; nothing to render\n"

      assert {:ok, ""} =
               render([@scene | ~w(-o #{dir}/f_##.png --frames 1-3 --continue -q)] ++ @tiny)

      assert Enum.map(1..3, &File.read!(Path.join(dir, "f_0#{&1}.png"))) == ~w(whole whole whole)
    end

    test "--continue: one frame not there yet (empty, as a crash could not leave it) is rendered",
         %{tmp_dir: dir} do
      File.touch!(Path.join(dir, "f_05.png"))
      {:ok, out} = render([@scene | ~w(-o #{dir}/f_##.png --frame 5 --continue)] ++ @tiny)
      assert out =~ "wrote #{dir}/f_05.png (16x12)"
      assert <<0x89, "PNG", _::binary>> = File.read!(Path.join(dir, "f_05.png"))
    end

    test "one file per frame, each the same as that frame rendered alone", %{tmp_dir: dir} do
      # a window smaller than the sequence: frames leave it as the command writes them
      args =
        ~w(-o #{dir}/f_##.png --frames 2-4 --window 1 --stats #{dir}/s.json --timeline #{dir}/t.svg)

      {:ok, out} = render([@scene | args] ++ @tiny)

      assert out =~
               ~r/wrote 3 frames \(16x12\), #{Regex.escape(dir)}\/f_02.png to #{Regex.escape(dir)}\/f_04.png, \d+\.\d{3} s per frame\n/

      for n <- 2..4,
          do:
            assert(
              out =~
                ~r/\n  frame #{n}: done at \d+\.\d{3} s \(\d+\.\d{3} s in flight\), 4 atoms, \d+ rays, f_0#{n}.png\n/
            )

      assert out =~ "with 2 children\n"
      assert out =~ "wrote #{dir}/s.json\nwrote #{dir}/t.svg\n"
      assert Enum.sort(File.ls!(dir)) == ~w(f_02.png f_03.png f_04.png s.json t.svg)

      for n <- 2..4 do
        {:ok, _} = render([@scene | ~w(-o #{dir}/alone.png --frame #{n} -q)] ++ @tiny)

        assert File.read!(Path.join(dir, "f_0#{n}.png")) ==
                 File.read!(Path.join(dir, "alone.png")),
               "frame #{n}"
      end
    end

    test "--continue renders only the frames not there, at the whole sequence's clock", %{
      tmp_dir: dir
    } do
      {:ok, _} = render([@scene | ~w(-o #{dir}/f_#.exr --frames 1-3 -q)] ++ @tiny)
      first = Enum.map(1..3, &File.read!(Path.join(dir, "f_#{&1}.exr")))
      inodes = Enum.map(1..3, &File.stat!(Path.join(dir, "f_#{&1}.exr")).inode)
      File.rm!(Path.join(dir, "f_2.exr"))
      # an empty file is no frame (a write is atomic: never one a render left)
      File.write!(Path.join(dir, "f_3.exr"), "")

      {:ok, out} = render([@scene | ~w(-o #{dir}/f_#.exr --frames 1-3 --continue)] ++ @tiny)
      assert out =~ "--continue: skipping 1 of 3 frames already written, rendering 2\n"

      assert out =~
               ~r/wrote 2 frames \(16x12\), #{Regex.escape(dir)}\/f_2.exr to #{Regex.escape(dir)}\/f_3.exr, \d+\.\d{3} s per frame\n/

      refute out =~ "frame 1:"
      # frame 1 untouched, 2 and 3 rendered again, as before
      assert File.stat!(Path.join(dir, "f_1.exr")).inode == hd(inodes)
      assert Enum.map(1..3, &File.read!(Path.join(dir, "f_#{&1}.exr"))) == first
    end

    test "an animated scene with a # and no --frames renders every frame", %{tmp_dir: dir} do
      scene = Path.join(dir, "three.toml")

      File.write!(scene, """
      [animation]
      frames = 3

      [camera]
      from = [0.0, 0.0, 5.0]
      at = [0.0, 0.0, 0.0]

      [camera.animate.from]
      keys = [{ clock = 0.0, value = [0.0, 0.0, 5.0] }, { clock = 1.0, value = [0.0, 2.0, 5.0] }]

      [[lights]]
      position = [5.0, 5.0, 5.0]

      [[objects]]
      type = "sphere"
      center = [0.0, 0.0, 0.0]
      radius = 1.0
      """)

      {:ok, ""} = render([scene | ~w(-o #{dir}/f_##.png -q)] ++ @tiny)
      assert Enum.sort(File.ls!(dir)) == ~w(f_01.png f_02.png f_03.png three.toml)
      # without a #, frame 1 alone, as ever
      {:ok, _} = render([scene | ~w(-o #{dir}/one.png -q)] ++ @tiny)
      assert File.read!(Path.join(dir, "one.png")) == File.read!(Path.join(dir, "f_01.png"))
    end
  end

  describe "the pixels' format" do
    # The format each job of the test used, from the jobs' ends.
    setup do
      me = self()
      id = {__MODULE__, make_ref()}

      :ok =
        RingTracer.Telemetry.attach(
          id,
          [:ring_tracer, :job, :stop],
          fn _, _, %{reply: reply}, _ ->
            with {:ok, raw} <- reply, do: send(me, {:pixels, raw.pixel_format, raw.tinted != nil})
          end,
          nil
        )

      on_exit(fn -> RingTracer.Telemetry.detach(id) end)
    end

    @scene "priv/scenes/balls_s2.nff"
    @common ~w(--width 40 --height 30 --children 2 --atoms 3 --strategy static -q --progress none)

    defp reference(dir) do
      {:ok, r} =
        RingTracer.render(Path.expand(@scene),
          width: 40,
          height: 30,
          children: 2,
          atoms: 3,
          strategy: :static
        )

      :ok = RingTracer.Image.write(r, Path.join(dir, "ref.png"))
      :ok = RingTracer.Image.write(r, Path.join(dir, "ref.exr"))
      :ok = RingTracer.Report.Ownership.write(r, Path.join(dir, "ref_own.png"))
      assert_receive {:pixels, :float, false}
      &File.read!(Path.join(dir, &1))
    end

    test "8-bit when every image is a PNG, the same files as of floats", %{tmp_dir: dir} do
      read = reference(dir)

      {:ok, _} =
        render([@scene, "-o", "#{dir}/a.png", "--ownership", "#{dir}/own.png"] ++ @common)

      assert_receive {:pixels, :srgb8, true}
      assert read.("a.png") == read.("ref.png")
      assert read.("own.png") == read.("ref_own.png")

      {:ok, _} = render([@scene, "-o", "#{dir}/b.png"] ++ @common)
      assert_receive {:pixels, :srgb8, false}
      assert read.("b.png") == read.("ref.png")
    end

    test "floats when an image is an EXR, which is unchanged", %{tmp_dir: dir} do
      read = reference(dir)

      {:ok, _} =
        render([@scene, "-o", "#{dir}/a.exr", "--ownership", "#{dir}/own.png"] ++ @common)

      assert_receive {:pixels, :float, false}
      assert read.("a.exr") == read.("ref.exr")
      assert read.("own.png") == read.("ref_own.png")
    end

    test "a sequence of PNGs in 8 bits, of EXRs in floats", %{tmp_dir: dir} do
      scene = "priv/scenes/whitted_orbit.toml"
      args = ~w(--frames 1-2 --width 24 --height 16 --children 2 --atoms 2 -q --progress none)

      {:ok, _} = render([scene, "-o", "#{dir}/f_#.png"] ++ args)
      assert_receive {:pixels, :srgb8, false}
      {:ok, _} = render([scene, "-o", "#{dir}/g_#.exr"] ++ args)
      assert_receive {:pixels, :float, false}

      for n <- 1..2 do
        floats = RingTracer.TestScenes.reference("whitted_orbit.toml", 24, 16, frame: n)
        {:ok, png} = RingTracer.Image.png(24, 16, floats)
        assert File.read!(Path.join(dir, "f_#{n}.png")) == png
        :ok = RingTracer.Image.write(Path.join(dir, "r_#{n}.exr"), 24, 16, floats)

        assert File.read!(Path.join(dir, "g_#{n}.exr")) ==
                 File.read!(Path.join(dir, "r_#{n}.exr"))
      end
    end
  end
end
