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
          {[bogus: 1], ":bogus"}
        ] do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: m}} =
               Options.validate(opt)

      assert m =~ message
    end
  end
end
