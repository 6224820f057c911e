defmodule RingTracer.FailureTest do
  use ExUnit.Case, async: false
  @moduletag timeout: 20_000

  alias RingTracer.TestScenes

  import RingTracer.TestScenes, only: [children: 0]

  @scene "balls_s2.nff"
  @opts [children: 4, atoms: 12, width: 96, height: 72, speeds: [3]]

  setup_all do
    {:ok, reference: TestScenes.reference(@scene, 96, 72)}
  end

  defp grandchild(child) do
    {:links, links} = Process.info(child, :links)
    sup = Process.whereis(RingTracer.Children)
    Enum.find(links, &(is_pid(&1) and &1 != sup))
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
      {:ok, result} =
        render_killing(unquote(seed), fn -> Process.exit(Enum.random(children()), :kill) end)

      assert result.pixels == reference
      assert [%{reason: ":killed"}] = result.failures
      assert Enum.count(result.children, &Map.has_key?(&1, :failed)) == 1
      assert children() == []
    end
  end

  for strategy <- RingTracer.Strategy.names() do
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
               fail_pixel: 100
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

  test "cancel stops every process of the job" do
    {:ok, job} =
      RingTracer.render_async(TestScenes.path(@scene),
        children: 3,
        atoms: 50,
        width: 256,
        height: 256,
        speeds: [5]
      )

    id = job.id

    receive do
      {RingTracer, ^id, {:progress, _, _}} -> :ok
    end

    assert :ok = RingTracer.cancel(job)
    Process.sleep(50)
    assert children() == []
    assert DynamicSupervisor.which_children(RingTracer.Jobs) == []
  end
end
