defmodule RingTracer.Scene.WarningTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Scene.Warning

  alias RingTracer.Scene.Warning

  test "a warning prints as file:line: warning: message, and the omitted ones are counted" do
    warnings = [
      %Warning{file: "a.nff", line: 9, message: "sphere 's' has radius 0 and is not rendered"},
      %Warning{file: "m.obj", line: nil, message: "the mesh has no faces"}
    ]

    assert Warning.lines(warnings, 1) == [
             "a.nff:9: warning: sphere 's' has radius 0 and is not rendered",
             "m.obj: warning: the mesh has no faces",
             "warning: 1 more warning not shown"
           ]
  end
end
