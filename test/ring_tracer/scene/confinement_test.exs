defmodule RingTracer.Scene.ConfinementTest do
  # The files a scene names stay inside its folder (or an allowed one), are
  # regular files, and never leak into an error message.
  use ExUnit.Case, async: true

  alias RingTracer.Scene

  @moduletag :tmp_dir

  @camera """
  [camera]
  from = [0.0, 0.0, 5.0]
  at = [0.0, 0.0, 0.0]
  width = 16
  height = 16

  [[lights]]
  position = [5.0, 5.0, 5.0]
  """

  @quad """
  v 0 0 0
  v 1 0 0
  v 1 1 0
  f 1 2 3
  """

  defp toml_with_mesh(dir, file) do
    path = Path.join(dir, "scene.toml")
    File.write!(path, @camera <> "\n[[objects]]\ntype = \"mesh\"\nfile = \"#{file}\"\n")
    path
  end

  test "a mesh inside the scene's folder is read and shipped", %{tmp_dir: dir} do
    File.mkdir_p!(Path.join(dir, "meshes"))
    File.write!(Path.join(dir, "meshes/q.obj"), @quad)
    {:ok, scene} = Scene.load(toml_with_mesh(dir, "meshes/q.obj"))
    assert scene.source.includes == %{"meshes/q.obj" => @quad}
    assert scene.files == [Path.join(real(dir), "meshes/q.obj")]
    assert scene.path == Path.join(real(dir), "scene.toml")
  end

  for reference <- ["../../../../../../etc/passwd", "/etc/shadow", "/proc/self/environ"] do
    test "a mesh reference #{reference} out of the folder is refused", %{tmp_dir: dir} do
      reference = unquote(reference)
      assert {:error, error} = Scene.load(toml_with_mesh(dir, reference))
      assert error.reason == :invalid_scene
      assert error.message =~ "scene.toml:10:"
      assert error.message =~ reference
      refute error.message =~ "root:"
    end
  end

  test "a symlink out of the folder is refused, one inside it is followed", %{tmp_dir: dir} do
    outside = Path.join(dir, "outside")
    inside = Path.join(dir, "scene_dir")
    File.mkdir_p!(outside)
    File.mkdir_p!(inside)
    File.write!(Path.join(outside, "q.obj"), @quad)
    File.write!(Path.join(inside, "real.obj"), @quad)
    File.ln_s!(Path.join(outside, "q.obj"), Path.join(inside, "escape.obj"))
    File.ln_s!("real.obj", Path.join(inside, "alias.obj"))

    assert {:error, error} = Scene.load(toml_with_mesh(inside, "escape.obj"))
    assert error.message =~ "escape.obj"
    assert error.message =~ "outside"

    assert {:ok, _} = Scene.load(toml_with_mesh(inside, "alias.obj"))
    # --allow-dir lets the scene reach the other folder.
    assert {:ok, _} = Scene.load(toml_with_mesh(inside, "escape.obj"), allow_dirs: [outside])
  end

  test "an OBJ mtllib out of the folder is refused", %{tmp_dir: dir} do
    path = Path.join(dir, "m.obj")
    File.write!(path, "mtllib ../../../../../etc/passwd\n" <> @quad)
    assert {:error, error} = Scene.load(path)
    assert error.message =~ "etc/passwd"
    refute error.message =~ "root:"
  end

  test "a FIFO as the scene or as a mesh is refused at once", %{tmp_dir: dir} do
    fifo = Path.join(dir, "pipe.nff")
    {_, 0} = System.cmd("mkfifo", [fifo])
    task = Task.async(fn -> Scene.load(fifo) end)
    assert {:ok, {:error, error}} = Task.yield(task, 5_000)
    assert error.message =~ "pipe.nff"
    assert error.message =~ ~r/FIFO|not a regular file/i

    {_, 0} = System.cmd("mkfifo", [Path.join(dir, "pipe.obj")])
    task = Task.async(fn -> Scene.load(toml_with_mesh(dir, "pipe.obj")) end)
    assert {:ok, {:error, error}} = Task.yield(task, 5_000)
    assert error.message =~ "pipe.obj"
  end

  test "a file that is not a scene is never echoed", %{tmp_dir: dir} do
    path = Path.join(dir, "passwd.nff")
    File.write!(path, "root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/bin/sh\n")
    assert {:error, error} = Scene.load(path)
    assert error.message =~ "passwd.nff:1:"
    refute error.message =~ "root"
  end

  test "control characters in an echoed token are escaped", %{tmp_dir: dir} do
    path = Path.join(dir, "esc.nff")
    File.write!(path, "v\nfrom 0 0 \e[31mred\n")
    assert {:error, error} = Scene.load(path)
    refute error.message =~ "\e"
  end

  defp real(dir) do
    {out, 0} = System.cmd("realpath", [dir])
    String.trim(out)
  end
end
