defmodule RingTracer.ErrorTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Error

  alias RingTracer.Error

  @tag :tmp_dir
  test "a file error names the path and the reason, the same for every module", %{tmp_dir: dir} do
    missing = Path.join([dir, "gone", "x.png"])

    assert %Error{reason: :file, message: message} = Error.file(:file, missing, :enoent)
    assert message == "#{missing}: the folder #{Path.dirname(missing)} does not exist"

    assert {:error, %Error{reason: :file, message: ^message}} =
             RingTracer.Output.write(missing, "data")
  end

  @tag :tmp_dir
  test "file names with control characters reach no message raw", %{tmp_dir: dir} do
    evil = "b\e[32mG\u0085"
    # an unknown format, a missing file, an output folder that does not exist
    for {:error, %Error{message: message}} <- [
          RingTracer.Scene.load(Path.join(dir, evil <> ".xyz")),
          RingTracer.Scene.load(Path.join(dir, evil <> ".nff")),
          RingTracer.Output.write(Path.join([dir, evil, "x.json"]), "data")
        ] do
      refute message =~ ~r/[\x00-\x1f\x7f]|\xc2[\x80-\x9f]/, message
      assert message =~ "b\\u{1b}[32mG\\u{85}"
    end

    # a scene that loads, with a warning that names it
    scene = Path.join(dir, evil <> ".nff")

    File.write!(
      scene,
      "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 4 4\n" <>
        "l 0 5 5\nf 1 0 0 1 0 0 0 0\ns 0 0 0 0\n"
    )

    assert {:ok, %{warnings: [warning | _]}} = RingTracer.Scene.load(scene)
    shown = to_string(warning)
    refute shown =~ "\e", shown
    assert shown =~ "b\\u{1b}[32mG\\u{85}.nff:10: warning"
  end
end
