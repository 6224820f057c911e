defmodule RingTracer.Report.TimelineTest do
  use ExUnit.Case, async: true

  alias RingTracer.Report.Timeline

  doctest RingTracer.Report.Palette

  @moduletag :tmp_dir

  setup_all do
    {:ok, result} =
      RingTracer.render(RingTracer.TestScenes.path("balls_s1.nff"),
        children: 4,
        atoms: 8,
        width: 32,
        height: 24,
        speeds: [1, 1, 4, 1]
      )

    %{result: result}
  end

  defp parse(svg) do
    {doc, []} = :xmerl_scan.string(String.to_charlist(IO.iodata_to_binary(svg)), quiet: true)
    doc
  end

  defp xpath(doc, path), do: :xmerl_xpath.string(String.to_charlist(path), doc)

  test "one atom bar per atom, one lane per child, valid XML", %{result: result} do
    doc = parse(Timeline.svg(result))
    assert length(xpath(doc, "//rect[@class='atom']")) == length(result.atoms)
    assert length(xpath(doc, "//rect[@class='lane']")) == length(result.children)
    svg = IO.iodata_to_binary(Timeline.svg(result))
    assert svg =~ "child 2 (speed 4)"
    assert svg =~ "strategy ring"
    assert svg =~ "makespan/ideal"
    assert svg =~ ~s(marker-end="url(#arrow-)
  end

  test "bars are coloured by original owner and sit in the tracer's lane", %{result: result} do
    atom = %{hd(result.atoms) | atom: 0, owner: 3, child: 1}
    result = %{result | atoms: [atom], events: []}
    svg = IO.iodata_to_binary(Timeline.svg(result))
    [bar] = Regex.run(~r/<rect class="atom"[^>]*>/, svg)
    assert bar =~ ~s(fill="#{RingTracer.Report.Palette.hex(3)}")
    assert svg =~ "owner child 3, traced by child 1"
  end

  test "text is escaped", %{result: result} do
    result = %{result | strategy: :"a<b&\"c'"}
    doc = parse(Timeline.svg(result))
    assert [_] = xpath(doc, "//text[@class='header']")
  end

  test "write/2 writes the SVG and reports unwritable paths", %{result: result, tmp_dir: dir} do
    path = Path.join([dir, "timeline.svg"])
    assert :ok = Timeline.write(result, path)
    assert "<?xml" <> _ = File.read!(path)

    # Outputs go only where the user pointed: a missing folder is an error,
    # not made.
    assert {:error, %RingTracer.Error{reason: :file, message: m}} =
             Timeline.write(result, Path.join([dir, "sub", "timeline.svg"]))

    assert m =~ "does not exist"
    refute File.exists?(Path.join(dir, "sub"))

    File.write!(Path.join(dir, "file"), "")

    assert {:error, %RingTracer.Error{reason: :file, message: m}} =
             Timeline.write(result, Path.join([dir, "file", "x.svg"]))

    assert m =~ "x.svg"
  end

  test "scales to a simulated 1024-child ring" do
    {:ok, result} = RingTracer.simulate(children: 1024, atoms: 2, costs: 1000)
    doc = parse(Timeline.svg(result))
    assert length(xpath(doc, "//rect[@class='atom']")) == 2048
    assert length(xpath(doc, "//rect[@class='lane']")) == 1024
    [height] = xpath(doc, "/svg/@height")
    {h, ""} = Float.parse(to_string(elem(height, 8)))
    assert h >= 2 * 1024
  end
end
