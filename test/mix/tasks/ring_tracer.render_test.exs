defmodule Mix.Tasks.RingTracer.RenderTest do
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  @tag :tmp_dir
  test "renders a scene to a PNG and says where", %{tmp_dir: dir} do
    out = Path.join(dir, "tetra.png")

    output =
      capture_io(fn ->
        Mix.Tasks.RingTracer.Render.run([
          "priv/scenes/tetra_s1.nff",
          "--out",
          out,
          "--children",
          "3",
          "--atoms",
          "4",
          "--width",
          "64",
          "--height",
          "64"
        ])
      end)

    assert output =~ "wrote #{out} (64x64)"
    assert output =~ "child 2:"
    assert <<137, "PNG", _::binary>> = File.read!(out)
  end

  test "a missing scene stops with its name" do
    assert_raise Mix.Error, ~r/missing\.nff/, fn ->
      Mix.Tasks.RingTracer.Render.run(["missing.nff", "--out", "x.png"])
    end
  end
end
