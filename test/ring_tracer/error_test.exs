defmodule RingTracer.ErrorTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Error

  alias RingTracer.Error

  @tag :tmp_dir
  test "a file error names the path and the reason, the same for every module", %{tmp_dir: dir} do
    missing = Path.join([dir, "gone", "x.png"])

    assert %Error{reason: :file, message: message} = Error.file(:file, missing, :enoent)
    assert message == "#{missing}: the folder #{Path.dirname(missing)} does not exist"

    assert {:error, %Error{reason: :file, message: ^message}} =
             RingTracer.Output.write(missing, "data")
  end
end
