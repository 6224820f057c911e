defmodule RingTracer.Chaos.FarmTest do
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag timeout: 180_000

  alias RingTracer.Chaos.Farm.Soak

  test "a short seeded farm soak: the head restarted, a worker killed, one frozen, one " <>
         "added; every job done, no frame lost, stored twice or differing" do
    # Seed 3: 15 frames, the faults due by the 6th (Schedule.new/1), so that
    # each lands while the queue runs.
    one_each = [head_kill: 1, worker_kill: 1, worker_freeze: 1, worker_add: 1]
    me = self()

    {:ok, report} =
      Soak.run([seed: 3, jobs: 8, faults: one_each], fn line -> send(me, {:event, line}) end)

    events = for {:event, line} <- Process.info(self(), :messages) |> elem(1), do: line
    what = Enum.join([Soak.format(report) | events], "\n")

    assert %{jobs: 8, done: 8, lost: 0, twice: 0, mismatches: 0, wrong: []} = report.verdict,
           what

    assert report.verdict.frames > 8
    # every fault was injected while the queue ran
    assert Map.take(report.faults, [:head_kill, :worker_kill, :worker_freeze, :worker_add]) ==
             %{head_kill: 1, worker_kill: 1, worker_freeze: 1, worker_add: 1},
           what

    assert {report.faults.skipped, report.faults.late} == {0, 0}, what
    assert Soak.passed?(report)
    assert Soak.format(report) =~ ~r/frames lost\s+0/
    assert_received {:event, "fault head_kill" <> _}
    # no peer node of the soak is left
    assert Enum.filter(Node.list(), &String.starts_with?(Atom.to_string(&1), "farm")) == []
  end
end
