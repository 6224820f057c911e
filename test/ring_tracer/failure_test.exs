defmodule RingTracer.FailureTest do
  use ExUnit.Case, async: false

  import RingTracer.Test.Wait
  @moduletag timeout: 20_000

  alias RingTracer.TestScenes

  import RingTracer.TestScenes, only: [children: 0]

  @scene "balls_s2.nff"
  # Slow enough (an atom of 144 pixels takes tens of milliseconds) that the
  # job is still running when the test, woken by a progress message on a
  # busy machine, picks its victim among the children.
  @opts [children: 4, atoms: 12, width: 96, height: 72, speeds: [50]]

  setup_all do
    {:ok, reference: TestScenes.reference(@scene, 96, 72)}
  end

  # The child's grandchild, or nil if the child has just ended (the job
  # completed while the test, on a busy machine, still read its progress).
  defp grandchild(child) do
    case Process.info(child, :links) do
      {:links, links} ->
        sup = Process.whereis(RingTracer.Children)
        Enum.find(links, &(is_pid(&1) and &1 != sup))

      nil ->
        nil
    end
  end

  defp render_killing(seed, victim_fun, opts \\ []) do
    :rand.seed(:exsss, {seed, seed, seed})
    {:ok, job} = RingTracer.render_async(TestScenes.path(@scene), Keyword.merge(@opts, opts))
    id = job.id
    # Wait for a random number of atoms to arrive, then kill.
    kill_after = Enum.random(1..30)

    result =
      Stream.repeatedly(fn ->
        receive do
          {RingTracer, ^id, msg} -> msg
        end
      end)
      |> Enum.reduce_while(0, fn
        {:progress, done, _total}, acc ->
          if done == kill_after, do: victim_fun.()
          {:cont, acc}

        result, _ ->
          {:halt, result}
      end)

    result
  end

  for seed <- 1..4 do
    test "killing a grandchild mid-render still gives the identical image (seed #{seed})", %{
      reference: reference
    } do
      {:ok, result} =
        render_killing(unquote(seed), fn ->
          child = Enum.random(children())
          if gc = grandchild(child), do: Process.exit(gc, :kill)
        end)

      assert result.pixels == reference
      assert Enum.sum(Enum.map(result.children, & &1.grandchild_restarts)) >= 0
    end

    test "killing a child mid-render still gives the identical image (seed #{seed})", %{
      reference: reference
    } do
      # The victim holds the job's first atom until it is killed, so the job
      # cannot end before the kill however late the test acts.
      ref = make_ref()
      kernel = {RingTracer.Test.FaultyKernel, block_first: {node(), self(), ref}}

      kill = fn ->
        assert_receive {:blocked, ^ref, held}, 10_000
        Process.exit(RingTracer.Test.FaultyKernel.child_of(held), :kill)
      end

      {:ok, result} = render_killing(unquote(seed), kill, kernel: kernel)

      assert result.pixels == reference
      assert [%{reason: ":killed"}] = result.failures
      assert Enum.count(result.children, &(&1.failed != nil)) == 1
      assert children() == []
    end
  end

  for strategy <- RingTracer.Strategies.names() do
    test "killing a child under #{strategy} still completes", %{reference: reference} do
      kill = fn -> Process.exit(Enum.random(children()), :kill) end
      {:ok, result} = render_killing(7, kill, strategy: unquote(strategy))
      assert result.pixels == reference
    end
  end

  test "killing every child fails the job with a clear reason" do
    assert {:error, %RingTracer.Error{reason: :render_failed, message: message}} =
             render_killing(3, fn -> Enum.each(children(), &Process.exit(&1, :kill)) end)

    assert message =~ "every child exited"
  end

  test "a kernel panic is retried, then fails the job cleanly, and the VM goes on" do
    assert {:error, %RingTracer.Error{reason: :render_failed, message: message}} =
             RingTracer.render(TestScenes.path(@scene),
               children: 2,
               atoms: 4,
               width: 32,
               height: 32,
               kernel: {RingTracer.Test.FaultyKernel, fail_pixel: 100}
             )

    assert message =~ "atom"
    assert children() == []
    # Another job in the same VM is unaffected.
    assert {:ok, _} =
             RingTracer.render(TestScenes.path(@scene),
               children: 2,
               atoms: 4,
               width: 32,
               height: 32
             )
  end

  test "cancel stops every process of the job and sends exactly one final message, :cancelled" do
    {:ok, job} =
      RingTracer.render_async(TestScenes.path(@scene),
        children: 3,
        atoms: 50,
        width: 256,
        height: 256,
        speeds: [5]
      )

    id = job.id
    assert_receive {RingTracer, ^id, {:progress, _, _}}, 10_000
    assert :ok = RingTracer.cancel(job)
    Process.sleep(50)
    assert children() == []
    assert DynamicSupervisor.which_children(RingTracer.Jobs) == []
    assert_receive {RingTracer, ^id, {:error, %RingTracer.Error{reason: :cancelled}}}
    refute_receive {RingTracer, ^id, {:error, _}}, 200
    refute_receive {RingTracer, ^id, {:ok, _}}, 0
  end

  test ":timeout covers the whole render and leaves no process behind" do
    t0 = System.monotonic_time(:millisecond)

    assert {:error, %RingTracer.Error{reason: :timeout}} =
             RingTracer.render(TestScenes.path(@scene),
               children: 2,
               atoms: 50,
               width: 256,
               height: 256,
               # Slow enough that the job cannot end within the timeout
               # however the machine's load moves the trace times.
               speeds: [1000],
               timeout: 200
             )

    assert System.monotonic_time(:millisecond) - t0 < 2_000
    assert eventually(fn -> children() == [] end)
    assert DynamicSupervisor.which_children(RingTracer.Jobs) == []
  end

  test "slowdown factors beyond the documented range are refused before any work" do
    assert {:error, %RingTracer.Error{reason: :invalid_option, message: message}} =
             RingTracer.render(TestScenes.path(@scene), speeds: [1.0e308])

    assert message =~ ":speeds"
  end

  test "with the application stopped, render/2 and render_async/2 answer with an error" do
    :ok = Application.stop(:ring_tracer)

    try do
      assert {:error, %RingTracer.Error{reason: :not_running}} =
               RingTracer.render(TestScenes.path(@scene))

      {:ok, job} = RingTracer.render_async(TestScenes.path(@scene))
      id = job.id
      assert_receive {RingTracer, ^id, {:error, %RingTracer.Error{reason: :not_running}}}
      assert {:error, %RingTracer.Error{reason: :not_running}} = RingTracer.simulate()
    after
      {:ok, _} = Application.ensure_all_started(:ring_tracer)
    end
  end
end
