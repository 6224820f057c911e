defmodule RingTracer.CLI.FramesTest do
  use ExUnit.Case, async: true
  doctest RingTracer.CLI.Frames

  alias RingTracer.CLI.Frames

  @moduletag :tmp_dir

  defp plan(opts, out, count \\ 24), do: Frames.plan(opts, out, count, "flight.toml")

  test "--frames A-B and N are inclusive ranges from 1; anything else says what it takes" do
    assert {:ok, %{numbers: [3, 4, 5], sequence?: true}} = plan([frames: "3-5"], "f_#.png")
    assert {:ok, %{numbers: [24], sequence?: false}} = plan([frames: "24"], "f_#.png")
    assert {:ok, %{numbers: [1, 2]}} = plan([frames: " 1 - 2 "], "f_#.png")

    for bad <- ["0", "0-3", "5-4", "a", "1-b", "1-2-3", "-3", "3-", ""] do
      assert {:usage, "--frames takes A-B" <> _} = plan([frames: bad], "f_#.png"), bad
    end
  end

  test "frames past the scene's last are refused naming the option, the scene and its count" do
    assert plan([frames: "20-25"], "f_#.png") ==
             {:usage, "--frames 20-25: flight.toml has 24 frames (1 to 24)"}

    assert plan([frames: "2"], "f_#.png", 1) ==
             {:usage, "--frames 2: flight.toml has 1 frame (a still)"}

    assert {:usage, "--frame must be at most 24 (the frames of flight.toml), got: 25"} =
             plan([frame: 25], "f_#.png")
  end

  test "a sequence needs one run of # in --out; one frame takes the number if there is one" do
    assert {:usage, "--out /x/f.exr: a sequence of 24 frames needs a run of # " <> rest} =
             plan([frames: "1-24"], "/x/f.exr")

    assert rest =~ "e.g. f_####.exr"

    assert {:usage, "--out f_#_#.png: one run of #" <> _} = plan([frame: 2], "f_#_#.png")
    assert {:usage, "--out f_#_#.png: one run of #" <> _} = plan([], "f_#_#.png")

    {:ok, one} = plan([frame: 7], "out/f_###.png")
    assert {one.numbers, one.sequence?, Frames.path(one, 7)} == {[7], false, "out/f_007.png"}

    {:ok, one} = plan([frames: "7-7"], "f.png")
    assert {one.numbers, one.sequence?, Frames.path(one, 7)} == {[7], false, "f.png"}
  end

  test "without --frame or --frames: every frame with a #, else frame 1 as ever" do
    assert {:ok, %{numbers: numbers, sequence?: true}} = plan([], "f_#.png")
    assert numbers == Enum.to_list(1..24)
    assert {:ok, %{numbers: [1], sequence?: false}} = plan([], "f.png")
    # a still with a # is its one frame, numbered
    assert {:ok, %{numbers: [1], sequence?: false} = p} = plan([], "f_##.png", 1)
    assert Frames.path(p, 1) == "f_01.png"
  end

  test "done/2: frames whose file is whole are done; empty files, folders and links are not",
       %{tmp_dir: dir} do
    {:ok, plan} = plan([frames: "1-6"], Path.join(dir, "f_##.png"))
    :ok = RingTracer.Output.write(Path.join(dir, "f_01.png"), "png")
    :ok = RingTracer.Output.write(Path.join(dir, "f_04.png"), "png")
    File.touch!(Path.join(dir, "f_02.png"))
    File.mkdir!(Path.join(dir, "f_03.png"))
    File.ln_s!(Path.join(dir, "f_01.png"), Path.join(dir, "f_05.png"))

    {:ok, held} = RingTracer.Output.open_dir(dir)
    assert Frames.done(plan, held) == {[1, 4], [2, 3, 5, 6]}
  end
end
