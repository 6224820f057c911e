defmodule RingTracer.OptionsTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Options

  alias RingTracer.Options

  test "children default to the schedulers online" do
    {:ok, opts} = Options.validate([])
    assert opts[:children] == System.schedulers_online()
    assert opts[:atoms] == 16
    assert opts[:layout] == :strips
  end

  test "each bad option is named" do
    for {opt, message} <- [
          {[depth: 0], ":depth"},
          {[cutoff: -1], ":cutoff"},
          {[spd: 1], ":spd"},
          {[nodes: ["a@b"]], ":nodes"},
          {[timeout: 0], ":timeout"},
          {[layout: :spiral], ":layout"},
          {[pixels: :rgb16], ":pixels must be one of [:float, :srgb8]"},
          {[ownership: :yes], ":ownership"},
          {[bogus: 1], ":bogus"}
        ] do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: m}} =
               Options.validate(opt)

      assert m =~ message
    end
  end

  test "the documented maxima are checked before any work, and the largest ring runs" do
    %{children: max_n, atoms: max_atoms} = Options.maxima()
    assert {:error, %RingTracer.Error{message: m}} = Options.validate(children: max_n + 1)
    assert m =~ ":children must be at most #{max_n}"

    assert {:error, %RingTracer.Error{message: m}} =
             Options.validate(children: 1, atoms: 1_000_000_000)

    assert m =~ "at most #{max_atoms} atoms"
    assert {:ok, _} = Options.validate(children: max_n, atoms: div(max_atoms, max_n))
    # Reduced here; the maxima were run at full size (see RingTracer.Options).
    {:ok, result} = RingTracer.simulate(children: 2048, atoms: 2, costs: 100)
    # One record per atom, or per piece of one (adaptive atoms).
    ids = Enum.map(result.atoms, & &1.atom)
    assert ids == Enum.uniq(ids)
    assert RingTracer.Job.Coverage.tiles?(RingTracer.Layout.new(4096, 1, 2048, 2), ids)
  end
end
