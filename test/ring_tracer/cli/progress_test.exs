defmodule RingTracer.CLI.ProgressTest do
  use ExUnit.Case, async: true
  doctest RingTracer.CLI.Progress

  alias RingTracer.CLI.Progress

  defp filled(text),
    do: text |> IO.iodata_to_binary() |> String.graphemes() |> Enum.count(&(&1 == "#"))

  test "on a terminal, one child's 16 atoms move the bar between atoms, never past the work" do
    p = Progress.new(:tty, 16, 0)
    {p, _} = Progress.atom(p, 100, 1_000)
    {_, at_atom} = Progress.tick(p, 1_000)
    {_, later} = Progress.tick(p, 1_500)
    {_, much_later} = Progress.tick(p, 60_000)

    assert filled(at_atom) == 2
    # Half an atom later the bar has moved...
    assert filled(later) == 3
    # ...but never to a second atom that has not arrived.
    assert filled(much_later) == 4
  end

  test "before the first atom the bar shows at once, empty, and says it is starting" do
    {_, text} = Progress.tick(Progress.new(:tty, 8, 0), 100)
    text = IO.iodata_to_binary(text)
    assert text =~ "0/8 atoms"
    assert text =~ "starting"
    assert filled(text) == 0
  end

  test "in a log, a plain line at most every 5 s, and nothing when quiet" do
    p = Progress.new(:log, 10, 0)
    {p, nil} = Progress.tick(p, 4_999)
    {p, line} = Progress.tick(p, 5_000)
    assert IO.iodata_to_binary(line) =~ ~r/^ringtracer: 0\/10 atoms \(0%\)/
    {_, nil} = Progress.tick(p, 9_000)
    assert {_, nil} = Progress.tick(Progress.new(:quiet, 10, 0), 60_000)
  end
end
