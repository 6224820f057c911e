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

  @tag :tmp_dir
  test "takes the command's sequence options: numbered files, --frames, --continue", %{
    tmp_dir: dir
  } do
    args =
      ~w(priv/scenes/whitted_orbit.toml --out #{dir}/o_###.png --frames 47-48 --width 16 --children 2 --progress none)

    output = capture_io(fn -> Mix.Tasks.RingTracer.Render.run(args) end)
    assert output =~ "wrote 2 frames (16x12), #{dir}/o_047.png to #{dir}/o_048.png"
    assert File.ls!(dir) |> Enum.sort() == ~w(o_047.png o_048.png)

    output = capture_io(fn -> Mix.Tasks.RingTracer.Render.run(args ++ ["--continue"]) end)
    assert output == "--continue: all 2 frames are already written; nothing to render\n"

    assert_raise Mix.Error, ~r/--out .*o.png: a sequence of 2 frames needs a run of #/, fn ->
      Mix.Tasks.RingTracer.Render.run(List.replace_at(args, 2, "#{dir}/o.png"))
    end
  end

  @tag :tmp_dir
  test "prints the scene's warnings to stderr with file and line, then renders", %{tmp_dir: dir} do
    scene = Path.join(dir, "odd.nff")

    File.write!(
      scene,
      "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 16 16\nl 1 2 3\n" <>
        "s 0 0 0 0\ns 0 0 0 1\n"
    )

    out = Path.join(dir, "odd.png")
    args = [scene, "--out", out, "--children", "2", "--atoms", "2"]
    parent = self()

    stderr =
      capture_io(:stderr, fn ->
        stdout = capture_io(fn -> Mix.Tasks.RingTracer.Render.run(args) end)
        send(parent, {:stdout, stdout})
      end)

    assert stderr =~ "odd.nff:8: warning: sphere 's' has radius 0 and is not rendered\n"
    assert_received {:stdout, stdout}
    assert stdout =~ "wrote #{out} (16x16)"
    refute stdout =~ "warning:"
    assert <<137, "PNG", _::binary>> = File.read!(out)
  end

  test "--cookie is refused even without --nodes: the secret would be on the command line" do
    assert_raise Mix.Error, ~r/--cookie-file/, fn ->
      Mix.Tasks.RingTracer.Render.run([
        "priv/scenes/tetra_s1.nff",
        "--out",
        "x.png",
        "--cookie",
        "s"
      ])
    end
  end

  test "a missing scene stops with its name" do
    assert_raise Mix.Error, ~r/missing\.nff/, fn ->
      Mix.Tasks.RingTracer.Render.run(["missing.nff", "--out", "x.png"])
    end
  end

  describe "outputs are checked before any tracing" do
    setup %{tmp_dir: dir} do
      scene = Path.join(dir, "scene.nff")
      File.cp!("priv/scenes/tetra_s1.nff", scene)
      {:ok, scene: scene, bytes: File.read!(scene)}
    end

    defp render!(args), do: capture_io(fn -> Mix.Tasks.RingTracer.Render.run(args) end)

    @tag :tmp_dir
    test "--timeline over the scene is refused and the scene is intact", %{
      tmp_dir: dir,
      scene: scene,
      bytes: bytes
    } do
      out = Path.join(dir, "a.png")

      assert_raise Mix.Error, ~r/--timeline .*scene\.nff: the timeline must end in \.svg/, fn ->
        render!([scene, "--out", out, "--timeline", scene])
      end

      assert File.read!(scene) == bytes
      refute File.exists?(out)
    end

    @tag :tmp_dir
    test "the scene itself, under a name with the right extension, is refused", %{
      tmp_dir: dir,
      scene: scene,
      bytes: bytes
    } do
      link = Path.join(dir, "scene.svg")
      File.ln_s!(scene, link)

      assert_raise Mix.Error, ~r/would overwrite .*scene\.nff, which this render reads/, fn ->
        render!([scene, "--out", Path.join(dir, "a.png"), "--timeline", link])
      end

      assert File.read!(scene) == bytes
    end

    @tag :tmp_dir
    test "a file the scene references is an input too", %{tmp_dir: dir} do
      mesh = Path.join(dir, "m.obj")
      File.write!(mesh, "mtllib colours.svg\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
      library = Path.join(dir, "colours.svg")
      File.write!(library, "newmtl red\nKd 1 0 0\n")

      assert_raise Mix.Error, ~r/--timeline .*colours\.svg: would overwrite/, fn ->
        render!([mesh, "--out", Path.join(dir, "a.png"), "--timeline", library])
      end

      assert File.read!(library) == "newmtl red\nKd 1 0 0\n"
      refute File.exists?(Path.join(dir, "a.png"))
    end

    @tag :tmp_dir
    test "two outputs that are one file are refused", %{tmp_dir: dir, scene: scene} do
      out = Path.join(dir, "a.png")

      assert_raise Mix.Error, ~r/--ownership .*a\.png: is the same file as --out/, fn ->
        render!([scene, "--out", out, "--ownership", out])
      end

      refute File.exists?(out)
    end

    @tag :tmp_dir
    test "bad extensions and missing folders are refused before the image is written", %{
      tmp_dir: dir,
      scene: scene
    } do
      assert_raise Mix.Error, ~r/--out .*a\.jpg: the image must end in \.png or \.exr/, fn ->
        render!([scene, "--out", Path.join(dir, "a.jpg")])
      end

      out = Path.join(dir, "a.png")

      assert_raise Mix.Error, ~r/--stats .*s\.txt: the statistics must end in/, fn ->
        render!([scene, "--out", out, "--stats", Path.join(dir, "s.txt")])
      end

      assert_raise Mix.Error, ~r/the folder .*nowhere does not exist/, fn ->
        render!([scene, "--out", Path.join([dir, "nowhere", "a.png"])])
      end

      assert File.ls!(dir) == ["scene.nff"]
    end

    @tag :tmp_dir
    test "a failed write leaves the earlier file untouched and no temporary file", %{
      tmp_dir: dir
    } do
      out = Path.join(dir, "a.png")
      File.write!(out, "earlier")
      assert {:error, _} = RingTracer.Image.write(out, 2, 2, <<0::96>>)
      assert File.read!(out) == "earlier"
      assert File.ls!(dir) |> Enum.sort() == ["a.png", "scene.nff"]
    end
  end
end
