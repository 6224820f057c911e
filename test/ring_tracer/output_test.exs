defmodule RingTracer.OutputTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Output

  @moduletag :tmp_dir

  test "a hard link to an input is that input", %{tmp_dir: dir} do
    scene = Path.join(dir, "s.nff")
    File.write!(scene, "v\n")
    link = Path.join(dir, "s.svg")
    File.ln!(scene, link)
    assert {:error, error} = RingTracer.Output.check([timeline: link], [scene])
    assert error.message =~ "would overwrite"
  end

  test "an existing folder in place of a file is refused", %{tmp_dir: dir} do
    File.mkdir_p!(Path.join(dir, "a.png"))
    assert {:error, error} = RingTracer.Output.check([image: Path.join(dir, "a.png")], [])
    assert error.message =~ "is a directory"
  end

  test "a file replaced keeps its permissions; a new one gets :mode or the umask's",
       %{tmp_dir: dir} do
    mode = fn name -> Bitwise.band(File.stat!(Path.join(dir, name)).mode, 0o7777) end
    File.write!(Path.join(dir, "plain"), "")

    :ok = RingTracer.Output.write(Path.join(dir, "fresh.json"), "{}")
    assert mode.("fresh.json") == mode.("plain")
    :ok = RingTracer.Output.write(Path.join(dir, "asked.json"), "{}", mode: 0o640)
    assert mode.("asked.json") == 0o640

    File.chmod!(Path.join(dir, "fresh.json"), 0o600)
    :ok = RingTracer.Output.write(Path.join(dir, "fresh.json"), "[]", mode: 0o666)
    assert {mode.("fresh.json"), File.read!(Path.join(dir, "fresh.json"))} == {0o600, "[]"}
    # nothing is left beside them
    assert Enum.sort(File.ls!(dir)) == ["asked.json", "fresh.json", "plain"]
  end
end
