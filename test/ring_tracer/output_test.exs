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
end
