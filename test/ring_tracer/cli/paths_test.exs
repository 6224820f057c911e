defmodule RingTracer.CLI.PathsTest do
  use ExUnit.Case, async: false
  doctest RingTracer.CLI.Paths

  test "relative paths resolve against the caller's folder" do
    System.put_env("RINGTRACER_CWD", "/somewhere/else")

    try do
      assert RingTracer.CLI.Paths.expand("a.png") == "/somewhere/else/a.png"

      assert RingTracer.CLI.Paths.expand([out: "a.png", n: 3], [:out]) ==
               [out: "/somewhere/else/a.png", n: 3]
    after
      System.delete_env("RINGTRACER_CWD")
    end
  end
end
