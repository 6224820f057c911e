defmodule RingTracer.Output.PatternTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Output.Pattern

  alias RingTracer.Output.Pattern

  test "the run's length is the fewest digits: shorter numbers are zero-padded, longer ones kept whole" do
    for {out, n, path} <- [
          {"f_#.png", 1, "f_1.png"},
          {"f_#.png", 10, "f_10.png"},
          {"f_####.png", 1, "f_0001.png"},
          {"f_####.png", 9999, "f_9999.png"},
          {"f_####.png", 1_000_000, "f_1000000.png"},
          {"####.exr", 48, "0048.exr"},
          {"/abs/dir/orbit_##_final.png", 3, "/abs/dir/orbit_03_final.png"}
        ] do
      {:ok, p} = Pattern.parse(out)
      assert Pattern.path(p, n) == path, "#{out} frame #{n}"
    end
  end

  test "only the file name is a pattern; a name with two runs is refused" do
    assert {:error, :none} = Pattern.parse("frames#1/orbit.png")
    assert {:error, :many} = Pattern.parse("f_#_#.png")
    assert {:error, :many} = Pattern.parse("##a##.png")
    refute Pattern.pattern?("frames#1/orbit.png")
    assert Pattern.pattern?("frames#1/orbit_#.png")
  end
end
