defmodule RingTracer.Cluster.CookieTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Cluster.Cookie
  doctest RingTracer.Cluster.Distribution
  doctest RingTracer.Cluster.TLS

  alias RingTracer.Cluster.Cookie

  @moduletag :tmp_dir

  test "an existing cookie is never replaced, and a new one is private", %{tmp_dir: dir} do
    path = Path.join(dir, "c")
    {:ok, ^path} = Cookie.create(path)
    assert Bitwise.band(File.stat!(path).mode, 0o777) == 0o600
    before = File.read!(path)
    assert {:error, error} = Cookie.create(path)
    assert error.message =~ "exists already"
    assert File.read!(path) == before
    # a symbolic link at the name is not followed, nor replaced
    victim = Path.join(dir, "victim")
    File.write!(victim, "")
    File.ln_s!(victim, Path.join(dir, "l"))
    assert {:error, error} = Cookie.create(Path.join(dir, "l"))
    assert error.message =~ "exists already"
    assert File.read!(victim) == ""
    assert File.ls!(dir) |> Enum.sort() == ["c", "l", "victim"]
  end

  test "the cookie's name only ever holds the whole secret, mode 0600", %{tmp_dir: dir} do
    # A watcher stats each new cookie's name as fast as it can while it is
    # made: it must never see the file unfinished (empty, or readable by
    # others), as a reader who opened it then would keep reading it.
    paths = for i <- 1..200, do: Path.join(dir, "c#{i}")
    parent = self()

    watcher =
      spawn_link(fn ->
        seen =
          Enum.flat_map(paths, fn path ->
            send(parent, {:watching, path})
            watch(path, [])
          end)

        send(parent, {:seen, seen})
      end)

    for path <- paths do
      assert_receive {:watching, ^path}, 5_000
      assert {:ok, ^path} = Cookie.create(path)
    end

    assert_receive {:seen, seen}, 10_000
    refute Process.alive?(watcher)
    assert Enum.uniq(seen) == [{0o600, 44}]
    # nothing else is left in the folder: no staged copy, no second name
    assert File.ls!(dir) |> Enum.sort() == Enum.sort(Enum.map(paths, &Path.basename/1))
    assert Enum.all?(paths, &(File.stat!(&1).links == 1))
  end

  # Stats `path` until it exists; returns what it saw of it then.
  defp watch(path, acc) do
    case File.stat(path) do
      {:ok, stat} -> [{Bitwise.band(stat.mode, 0o777), stat.size} | acc]
      {:error, :enoent} -> watch(path, acc)
    end
  end

  test "a cookie is read from this user's own closed file only, never through a link", %{
    tmp_dir: dir
  } do
    path = Path.join(dir, "c")
    {:ok, ^path} = Cookie.create(path)
    assert {:ok, _} = Cookie.read(path)
    # a link to a good cookie is not followed (another user may own the folder it is in)
    File.ln_s!(path, Path.join(dir, "l"))
    assert {:error, error} = Cookie.read(Path.join(dir, "l"))
    assert error.message =~ "l: the cookie file is a symbolic link (not followed"
    # a FIFO is refused at once, not waited on
    fifo = Path.join(dir, "fifo")
    {_, 0} = System.cmd("mkfifo", ["-m", "600", fifo])
    task = Task.async(fn -> Cookie.read(fifo) end)
    assert {:error, error} = Task.await(task, 5_000)
    assert error.message =~ "fifo: the cookie file is a FIFO (named pipe), not a regular file"
    big = Path.join(dir, "big")
    File.write!(big, String.duplicate("x", 4097))
    File.chmod!(big, 0o600)
    assert {:error, error} = Cookie.read(big)
    assert error.message =~ "big: the cookie file is too large (4097 bytes, at most 4096)"
    File.chmod!(path, 0o640)
    assert {:error, error} = Cookie.read(path)

    assert error.message =~
             "can be read by other users (mode 0640); fix it with: chmod 600 #{path}"
  end

  test "a missing or empty cookie file says how to make one", %{tmp_dir: dir} do
    assert {:error, error} = Cookie.read(Path.join(dir, "none"))
    assert error.message =~ "ringtracer cookie"
    empty = Path.join(dir, "empty")
    File.write!(empty, "\n")
    File.chmod!(empty, 0o600)
    assert {:error, error} = Cookie.read(empty)
    assert error.message =~ "empty"
  end
end
