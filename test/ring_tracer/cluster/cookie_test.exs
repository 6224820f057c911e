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
