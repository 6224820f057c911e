defmodule RingTracer.Cluster.BuildTest do
  @moduledoc """
  A node's build: stable, printable, and different when the code differs;
  two builds compared name both and what differs.
  """
  use ExUnit.Case, async: true

  alias RingTracer.Cluster.Build
  alias RingTracer.LocalCluster, as: Peers

  doctest Build

  test "the identity is stable across calls and is the code loaded now" do
    build = Build.identity()
    assert %Build{version: version, code: code, nif: nif} = build
    assert version == List.to_string(Application.spec(:ring_tracer, :vsn))
    assert byte_size(code) == 16
    # the NIF is loaded here, so its library was read
    assert is_binary(nif) and byte_size(nif) == 32
    assert Build.identity() == build
    # computed again (more modules loaded since: beam_lib's MD5 is theirs)
    assert Build.compute() == build
  end

  test "the short form is the version and 8 hex digits" do
    assert Build.short(Build.identity()) =~ ~r/^\d+\.\d+\.\d+\+[0-9a-f]{8}$/
    assert Build.short(:unknown) == "an unknown build"
  end

  test "two builds compared: the same is :ok, another names both and what differs" do
    ours = %Build{version: "0.1.0", code: "a", nif: "n"}
    assert Build.compare(:w@h, ours, ours) == :ok

    for {theirs, what} <- [
          {%{ours | version: "0.2.0"}, "the versions differ"},
          {%{ours | code: "b"}, "the code differs"},
          {%{ours | nif: nil}, "the NIF differs"},
          {:unknown, "does not tell its build"}
        ] do
      assert {:error, %RingTracer.Error{reason: :build_mismatch, message: message}} =
               Build.compare(:w@h, theirs, ours)

      named = if theirs == :unknown, do: "an unknown build", else: "build #{Build.short(theirs)}"
      assert message =~ "node w@h runs #{named}, node #{node()} runs build #{Build.short(ours)}"

      assert message =~ what
      assert Build.short(theirs) != Build.short(ours)
    end
  end

  test "this node's own check is :ok without a call" do
    assert Build.check(node()) == :ok
  end

  @tag :distributed
  test "a node that loads a changed module has another build" do
    Peers.ensure_distributed()
    {peer, n} = Peers.start("build")

    try do
      assert Peers.call(peer, n, Build, :compute, []) == Build.identity()
      assert Build.check(n) == :ok

      source = File.read!(RingTracer.Names.module_info(:compile)[:source])
      header = "defmodule RingTracer.Names do\n"
      assert source =~ header
      changed = String.replace(source, header, header <> "  def changed, do: true\n")
      Peers.call(peer, n, Code, :put_compiler_option, [:ignore_module_conflict, true])
      Peers.call(peer, n, Code, :compile_string, [changed])

      theirs = Peers.call(peer, n, Build, :compute, [])
      assert theirs.code != Build.identity().code
      assert theirs.version == Build.identity().version
      assert theirs.nif == Build.identity().nif
      assert {:error, error} = Build.compare(n, theirs)
      assert error.message =~ "the code differs"
    after
      Peers.stop(peer)
    end
  end
end
