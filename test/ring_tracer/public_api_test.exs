defmodule RingTracer.PublicAPITest do
  # The public API is a short list (docs/architecture.md, "The public
  # API"): every other module of the application is `@moduledoc false`.
  use ExUnit.Case, async: true

  @public [
    RingTracer,
    RingTracer.Cluster,
    RingTracer.Error,
    RingTracer.Farm,
    RingTracer.Frame,
    RingTracer.Image,
    RingTracer.Preview,
    RingTracer.Result,
    RingTracer.Scene,
    RingTracer.Scene.Warning,
    RingTracer.Strategy,
    RingTracer.Strategy.ParentView,
    RingTracer.Strategy.View,
    RingTracer.Telemetry
  ]

  defp documented?(module) do
    case Code.fetch_docs(module) do
      {:docs_v1, _, _, _, %{}, _, _} -> true
      {:docs_v1, _, _, _, :none, _, _} -> true
      {:docs_v1, _, _, _, :hidden, _, _} -> false
    end
  end

  # The application's own modules: neither the test support compiled into
  # it in the test build (test/support) nor protocol implementations.
  defp own?(module) do
    source = module.module_info(:compile)[:source] |> to_string()

    not String.contains?(source, "/test/support/") and
      not function_exported?(module, :__impl__, 1)
  end

  test "the documented modules are the public list and the Mix tasks, nothing else" do
    {:ok, modules} = :application.get_key(:ring_tracer, :modules)
    documented = modules |> Enum.filter(&(own?(&1) and documented?(&1))) |> MapSet.new()

    tasks =
      MapSet.new(modules, &to_string/1)
      |> Enum.filter(&String.starts_with?(&1, "Elixir.Mix.Tasks."))

    tasks = MapSet.new(tasks, &String.to_existing_atom/1)

    assert MapSet.difference(documented, MapSet.union(MapSet.new(@public), tasks)) |> Enum.sort() ==
             []

    for module <- @public, do: assert(documented?(module), "#{inspect(module)} has no docs")
  end

  test "docs/architecture.md lists exactly the public modules" do
    text = File.read!("docs/architecture.md")
    [_, section] = String.split(text, "## The public API", parts: 2)
    [section | _] = String.split(section, "\n## ", parts: 2)
    listed = Regex.scan(~r/`(RingTracer(?:\.[A-Z]\w*)*)`/, section) |> Enum.map(&List.last/1)
    assert Enum.sort(Enum.uniq(listed)) == Enum.sort(Enum.map(@public, &inspect/1))
  end
end
