defmodule RingTracer.TelemetryTest do
  use ExUnit.Case, async: false
  doctest RingTracer.Telemetry

  alias RingTracer.Telemetry

  test "a job emits start, one atom event per atom, and stop, in that order" do
    me = self()
    fwd = fn event, m, md, _ -> send(me, {event, m, md}) end

    for e <- [
          [:ring_tracer, :job, :start],
          [:ring_tracer, :atom, :stop],
          [:ring_tracer, :job, :stop]
        ],
        do: :ok = Telemetry.attach({:t, e}, e, fwd, nil)

    {:ok, _} =
      RingTracer.render("priv/scenes/tetra_s1.nff", width: 8, height: 8, children: 2, atoms: 3)

    for e <- [
          [:ring_tracer, :job, :start],
          [:ring_tracer, :atom, :stop],
          [:ring_tracer, :job, :stop]
        ],
        do: :ok = Telemetry.detach({:t, e})

    assert_received {[:ring_tracer, :job, :start], _, %{children: 2, atoms: 6, job: job}}

    dones =
      for _ <- 1..6,
          do: receive(do: ({[:ring_tracer, :atom, :stop], _, %{job: ^job} = md} -> md.done))

    assert Enum.sort(dones) == [1, 2, 3, 4, 5, 6]

    assert_received {[:ring_tracer, :job, :stop], %{duration: d}, %{job: ^job, outcome: :ok}}
                    when d > 0
  end

  test "a handler that raises is detached and the job goes on" do
    :ok =
      Telemetry.attach(
        :boom,
        [:ring_tracer, :atom, :stop],
        fn _, _, _, _ -> raise "boom" end,
        nil
      )

    ExUnit.CaptureLog.capture_log(fn ->
      assert {:ok, _} =
               RingTracer.render("priv/scenes/tetra_s1.nff",
                 width: 8,
                 height: 8,
                 children: 1,
                 atoms: 2
               )
    end)

    assert Telemetry.detach(:boom) == {:error, :not_found}
  end

  test "attaching an id twice is refused" do
    :ok = Telemetry.attach(:twice, [:x], fn _, _, _, _ -> :ok end, nil)

    assert Telemetry.attach(:twice, [:y], fn _, _, _, _ -> :ok end, nil) ==
             {:error, :already_exists}

    :ok = Telemetry.detach(:twice)
  end
end
