defmodule RingTracer.Report.StatsTest do
  use ExUnit.Case, async: true

  alias RingTracer.Report.Stats

  @moduletag :tmp_dir

  setup_all do
    {:ok, result} =
      RingTracer.render(RingTracer.TestScenes.path("balls_s1.nff"),
        children: 3,
        atoms: 4,
        width: 32,
        height: 24,
        speeds: [1, 3, 1]
      )

    %{result: result}
  end

  test "summary/1", %{result: result} do
    s = Stats.summary(result)
    assert s.makespan_us == result.elapsed_us
    assert s.ideal_us == result.ideal_us
    assert s.ratio == result.elapsed_us / result.ideal_us
    assert s.strategy == result.strategy
    assert s.atoms == 12 and s.width == 32 and s.height == 24
    assert s.messages == result.messages
    assert s.rays == result.rays
    idle = Enum.sum(Enum.map(result.children, & &1.idle_us))
    assert_in_delta s.idle_pct, 100 * idle / (3 * result.elapsed_us), 1.0e-9
    assert s.messages_total.count == Enum.sum(Enum.map(result.messages, fn {_, m} -> m.count end))
    assert_in_delta s.per_atom.messages, s.messages_total.count / 12, 1.0e-9
    assert [%{node: node} | _] = s.children
    assert is_binary(node)
  end

  test "JSON round-trips through jiffy", %{result: result, tmp_dir: dir} do
    path = Path.join(dir, "stats.json")
    assert :ok = Stats.write(result, path)
    json = :jiffy.decode(File.read!(path), [:return_maps])

    for {kind, %{count: c, bytes: b}} <- result.messages do
      assert %{"count" => ^c, "bytes" => ^b} = json["messages"][Atom.to_string(kind)]
    end

    assert map_size(json["messages"]) == map_size(result.messages)
    assert json["makespan_us"] == result.elapsed_us
    assert json["strategy"] == Atom.to_string(result.strategy)
    assert length(json["children"]) == 3
    assert hd(json["children"])["node"] == Atom.to_string(node())
  end

  test "nil becomes null in JSON", %{result: result, tmp_dir: dir} do
    path = Path.join(dir, "zero.json")
    assert :ok = Stats.write(%{result | ideal_us: 0}, path)
    assert %{"ratio" => :null} = :jiffy.decode(File.read!(path), [:return_maps])
  end

  test "CSV has a header and one line per child", %{result: result, tmp_dir: dir} do
    path = Path.join(dir, "stats.csv")
    assert :ok = Stats.write(result, path)
    [header | rows] = path |> File.read!() |> String.split("\n", trim: true)
    assert length(rows) == 3
    columns = String.split(header, ",")
    assert "index" in columns and "speed" in columns and "idle_us" in columns
    assert "rays_eye" in columns

    for {row, i} <- Enum.with_index(rows) do
      fields = String.split(row, ",")
      assert length(fields) == length(columns)
      assert hd(fields) == Integer.to_string(i)
    end
  end

  test "CSV quotes fields with commas and quotes", %{result: result} do
    [c | rest] = result.children
    result = %{result | children: [%{c | node: :"a,b\"c"} | rest]}
    [_header, first | _] = result |> Stats.csv() |> IO.iodata_to_binary() |> String.split("\n")
    assert first =~ ~s("a,b""c")
  end

  test "other extensions are errors naming the file", %{result: result, tmp_dir: dir} do
    path = Path.join(dir, "stats.xml")

    assert {:error, %RingTracer.Error{reason: :file, message: m}} = Stats.write(result, path)
    assert m =~ "stats.xml"
    refute File.exists?(path)
  end
end
