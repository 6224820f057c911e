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

  test "write_all's writes land in the folder it kept the old files in, opened once", %{
    tmp_dir: dir
  } do
    d = Path.join(dir, "d")
    other = Path.join(dir, "other")
    moved = Path.join(dir, "d_moved")
    File.mkdir!(d)
    File.mkdir!(other)
    [a, img] = [Path.join(d, "a.json"), Path.join(d, "i.png")]
    File.write!(a, "old")
    File.write!(img, "old image")
    pixels = for _ <- 1..3, into: <<>>, do: <<0.5::float-32-native>>

    # the folder's name leads elsewhere once the old files are kept (a link of
    # this user's, which a path would follow)
    swap = fn ->
      File.rename!(d, moved)
      File.ln_s!(other, d)
    end

    failing = {:error, RingTracer.Error.new(:file, "b.svg: no space left on device")}

    # the old files' folder is swapped away after the first write, before the image's
    writes = [
      {a, fn folder -> RingTracer.Output.write(a, "new", in: folder) end},
      {img,
       fn folder ->
         swap.()
         RingTracer.Image.write(img, 1, 1, pixels, in: folder)
       end}
    ]

    assert {:error, _} =
             RingTracer.Output.write_all(writes ++ [{Path.join(d, "b.svg"), fn _ -> failing end}])

    # put back where they were kept, nothing written through the new name
    assert File.ls!(other) == []
    assert File.read!(Path.join(moved, "a.json")) == "old"
    assert File.read!(Path.join(moved, "i.png")) == "old image"
    assert Enum.sort(File.ls!(moved)) == ["a.json", "i.png"]

    File.rm!(d)
    File.rename!(moved, d)

    assert :ok = RingTracer.Output.write_all(writes)

    assert File.ls!(other) == []
    assert File.read!(Path.join(moved, "a.json")) == "new"
    assert <<137, "PNG", _::binary>> = File.read!(Path.join(moved, "i.png"))
    assert Enum.sort(File.ls!(moved)) == ["a.json", "i.png"]
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

  test "a replaced output keeps its permission bits but never setuid, setgid or sticky",
       %{tmp_dir: dir} do
    path = Path.join(dir, "a.json")
    File.write!(path, "old")
    File.chmod!(path, 0o6755)
    assert Bitwise.band(File.stat!(path).mode, 0o7777) == 0o6755
    :ok = RingTracer.Output.write(path, "new", mode: 0o600)
    assert {Bitwise.band(File.stat!(path).mode, 0o7777), File.read!(path)} == {0o755, "new"}
  end

  test "a symbolic link at an output is replaced, never followed", %{tmp_dir: dir} do
    victim = Path.join(dir, "victim")
    File.write!(victim, "victim's")
    File.chmod!(victim, 0o644)
    link = Path.join(dir, "a.json")
    File.ln_s!(victim, link)
    :ok = RingTracer.Output.write(link, "{}", mode: 0o600)

    assert {File.read!(victim), File.stat!(victim).mode |> Bitwise.band(0o777)} ==
             {"victim's", 0o644}

    assert {:ok, %File.Stat{type: :regular}} = File.lstat(link)
  end

  test "a failed write_all puts back exactly what was there, links included, and leaves no hidden file",
       %{tmp_dir: dir} do
    target = Path.join(dir, "target.png")
    File.write!(target, "earlier")
    [link, file, new] = for n <- ["link.png", "file.json", "new.svg"], do: Path.join(dir, n)
    File.ln_s!("target.png", link)
    File.write!(file, "old")
    failing = fn -> {:error, RingTracer.Error.new(:file, "no space left on device")} end
    writes = fn last -> [{link, fn -> RingTracer.Output.write(link, "new") end}, last] end

    # fails after replacing the link, the file and making a new one; or before writing
    for last <- [
          {new, failing},
          {file, fn -> RingTracer.Output.write(file, "new") end}
        ] do
      all =
        writes.(last) ++
          [{file, fn -> RingTracer.Output.write(file, "new") end}, {new, failing}]

      all = Enum.uniq_by(all, &elem(&1, 0))
      assert {:error, _} = RingTracer.Output.write_all(all)
      assert {:ok, "target.png"} = File.read_link(link)
      assert File.read!(target) == "earlier"
      assert File.read!(file) == "old"
      refute File.exists?(new)
      assert Enum.sort(File.ls!(dir)) == ["file.json", "link.png", "target.png"]
    end

    # a write that fails before replacing anything leaves nothing either
    assert {:error, _} = RingTracer.Output.write_all([{file, failing}])
    assert Enum.sort(File.ls!(dir)) == ["file.json", "link.png", "target.png"]

    :ok = RingTracer.Output.write_all([{link, fn -> RingTracer.Output.write(link, "new") end}])
    assert {{:error, :einval}, "new"} == {File.read_link(link), File.read!(link)}
    assert Enum.sort(File.ls!(dir)) == ["file.json", "link.png", "target.png"]
  end

  test "the folder probe and private_dir work on the folder opened, not a name",
       %{tmp_dir: dir} do
    assert :ok = RingTracer.Output.check([stats: Path.join(dir, "a.json")], [])
    assert File.ls!(dir) == []
    private = Path.join(dir, "p")
    assert :ok = RingTracer.Output.private_dir(private)
    assert Bitwise.band(File.stat!(private).mode, 0o777) == 0o700
    assert {:error, :eexist} = RingTracer.Output.private_dir(private)
    File.ln_s!(private, Path.join(dir, "l"))
    assert {:error, :eexist} = RingTracer.Output.private_dir(Path.join(dir, "l"))
  end

  test "check_targets/2: each existing path must be a regular file, new names are fine", %{
    tmp_dir: dir
  } do
    [a, b, c] = for n <- 1..3, do: Path.join(dir, "f_#{n}.png")
    :ok = RingTracer.Output.write(a, "png")
    assert :ok = RingTracer.Output.check_targets(:image, [a, b])
    File.mkdir!(c)
    assert {:error, error} = RingTracer.Output.check_targets(:image, [a, b, c])
    assert error.message == "--out #{c}: exists and is a directory, not a file"
  end
end
