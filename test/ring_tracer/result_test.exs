defmodule RingTracer.ResultTest do
  use ExUnit.Case, async: true

  test "a result inspects as one line: size, time, ring, atoms and rays, not its pixels" do
    {:ok, r} =
      RingTracer.render("priv/scenes/tetra_s1.nff", width: 16, height: 12, children: 2, atoms: 3)

    text = inspect(r)
    refute text =~ "\n"

    assert text =~
             ~r/^#RingTracer.Result<16x12, [\d.]+ ms, 2 children \(ring\), 6 atoms, \d+ rays>$/
  end
end
