defmodule RingTracerTest do
  use ExUnit.Case, async: false
  doctest RingTracer

  alias RingTracer.TestScenes

  @scene "balls_s1.nff"

  defp job_processes do
    for sup <- [RingTracer.Jobs, RingTracer.Children],
        {_, pid, _, _} <- DynamicSupervisor.which_children(sup),
        do: pid
  end

  describe "determinism" do
    setup do
      {:ok, reference: TestScenes.reference(@scene, 40, 30)}
    end

    for n <- [1, 2, 3, 7], k <- [1, 5, 64] do
      test "N=#{n}, K=#{k} gives the single-process image", %{reference: reference} do
        {:ok, result} =
          RingTracer.render(TestScenes.path(@scene),
            children: unquote(n),
            atoms: unquote(k),
            width: 40,
            height: 30
          )

        assert result.pixels == reference
        # Each atom once, whole or in pieces (adaptive atoms) that tile it.
        assert Enum.sum(Enum.map(result.children, & &1.traced)) == length(result.atoms)
        layout = RingTracer.Layout.new(40, 30, unquote(n), unquote(k))
        assert RingTracer.Job.Coverage.tiles?(layout, Enum.map(result.atoms, & &1.atom))
        splits = Enum.sum(Enum.map(result.children, & &1.splits))
        assert length(result.atoms) == unquote(n * k) + splits
      end
    end

    test "property: any N, K and image size gives the single-process image" do
      gen =
        {:proper_types.integer(1, 9), :proper_types.integer(1, 12), :proper_types.integer(1, 23),
         :proper_types.integer(1, 17)}

      RingTracer.PropErCase.check(
        gen,
        fn {n, k, w, h} ->
          {:ok, result} =
            RingTracer.render(TestScenes.path(@scene), children: n, atoms: k, width: w, height: h)

          result.pixels == TestScenes.reference(@scene, w, h)
        end,
        40
      )
    end
  end

  test "every atom is traced exactly once and the stats add up" do
    {:ok, result} =
      RingTracer.render(TestScenes.path(@scene), children: 4, atoms: 8, width: 64, height: 48)

    stats = result.children
    assert length(stats) == 4
    # Every cut (adaptive atoms) makes one piece more.
    splits = Enum.sum(Enum.map(stats, & &1.splits))
    assert Enum.sum(Enum.map(stats, & &1.traced)) == 32 + splits
    ids = Enum.map(result.atoms, & &1.atom)
    assert RingTracer.Job.Coverage.tiles?(RingTracer.Layout.new(64, 48, 4, 8), ids)
    assert Enum.sum(Enum.map(stats, & &1.given)) == Enum.sum(Enum.map(stats, & &1.received))

    # Every consumed offer is exactly one hand-over.
    assert Enum.sum(Enum.map(stats, & &1.offers_consumed)) ==
             Enum.sum(Enum.map(stats, & &1.handovers))

    # Every child sent at least one offer, and its last one came back.
    assert Enum.all?(stats, &(&1.offers_sent >= 1))

    for c <- stats, do: assert(c.traced == c.own - c.given + c.received + c.splits)
    assert result.rays.eye == 64 * 48
    # Work units: one per ray, plus the boxes and primitives the rays were tested against.
    assert result.rays.work > result.rays.eye + result.rays.shadow
    # Every child that traced has a speed.
    for c <- stats, c.traced > 0, do: assert(RingTracer.Job.Stats.rate(c) > 0)
  end

  test "delayed hand-overs still give the complete, identical image" do
    reference = TestScenes.reference(@scene, 48, 32)

    opts = [children: 5, atoms: 6, width: 48, height: 32]
    strategy = RingTracer.Test.DelayedStrategy.wrap(opts, handover_delay: 40)
    {:ok, result} = RingTracer.render(TestScenes.path(@scene), [strategy: strategy] ++ opts)

    assert result.pixels == reference
    splits = Enum.sum(Enum.map(result.children, & &1.splits))
    assert Enum.sum(Enum.map(result.children, & &1.traced)) == 30 + splits
    ids = Enum.map(result.atoms, & &1.atom)
    assert RingTracer.Job.Coverage.tiles?(RingTracer.Layout.new(48, 32, 5, 6), ids)
  end

  test "no process of a job is left after it ends" do
    before = length(Process.list())

    {:ok, _} =
      RingTracer.render(TestScenes.path(@scene), children: 6, atoms: 3, width: 20, height: 10)

    assert job_processes() == []
    assert length(Process.list()) <= before + 1
  end

  test "a missing scene is an error naming the file" do
    assert {:error, %RingTracer.Error{reason: :file, message: message}} =
             RingTracer.render("no/such.nff")

    assert message =~ "no/such.nff"
  end

  test "an invalid scene is an error naming file and line" do
    path =
      TestScenes.tmp_scene(
        "bad.nff",
        "b 0 0 0\nv\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\np 2\n0 0 0\n1 0 0\n"
      )

    assert {:error, %RingTracer.Error{reason: :invalid_scene, message: message}} =
             RingTracer.render(path)

    assert message =~ "bad.nff:9"
  end

  test "a scene's warnings come back in the result, and nothing is printed" do
    path =
      TestScenes.tmp_scene(
        "odd.nff",
        "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 8 8\nl 1 2 3\n" <>
          "s 0 0 0 0\ns 0 0 0 1\n"
      )

    printed =
      ExUnit.CaptureIO.capture_io(:stderr, fn ->
        stdout =
          ExUnit.CaptureIO.capture_io(fn ->
            assert {:ok, result} = RingTracer.render(path, children: 2, atoms: 2)

            assert [%RingTracer.Scene.Warning{file: "odd.nff", line: 8}] = result.warnings
            assert result.warnings_omitted == 0
          end)

        assert stdout == ""
      end)

    assert printed == ""
    # a clean scene has none
    assert {:ok, %{warnings: []}} =
             RingTracer.render(TestScenes.path(@scene), children: 2, atoms: 2, width: 8, height: 8)
  end

  test "bad options are errors, not crashes" do
    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             RingTracer.render(TestScenes.path(@scene), children: 0)

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             RingTracer.render(TestScenes.path(@scene), colour: :red)

    assert {:error, %RingTracer.Error{reason: :invalid_option}} =
             RingTracer.render(TestScenes.path(@scene), width: 100_000, height: 100_000)
  end

  describe "a frame of an animated scene" do
    test "is the kernel's own render of that frame, and frame 1 is the default" do
      scene = TestScenes.path("whitted_orbit.toml")
      {:ok, first} = RingTracer.render(scene, children: 3, atoms: 4, width: 48, height: 36)
      assert first.pixels == TestScenes.reference("whitted_orbit.toml", 48, 36)

      {:ok, later} =
        RingTracer.render(scene, children: 3, atoms: 4, width: 48, height: 36, frame: 13)

      assert later.pixels == TestScenes.reference("whitted_orbit.toml", 48, 36, frame: 13)
      assert later.pixels != first.pixels
    end

    test "past the scene's last frame is an error naming the scene, before any work" do
      assert {:error, %RingTracer.Error{reason: :invalid_option, message: message}} =
               RingTracer.render(TestScenes.path("whitted_orbit.toml"), frame: 49)

      assert message ==
               "option :frame must be at most 48 (the frames of whitted_orbit.toml), got: 49"

      assert {:error, %RingTracer.Error{message: "option :frame must be at most 1" <> _}} =
               RingTracer.render(TestScenes.path(@scene), frame: 2)

      assert {:error, %RingTracer.Error{reason: :invalid_option}} =
               RingTracer.render(TestScenes.path(@scene), frame: 0)
    end
  end

  test "render! raises RingTracer.Error" do
    assert_raise RingTracer.Error, ~r/no\/such/, fn -> RingTracer.render!("no/such.nff") end
  end

  test "one side alone keeps the scene's aspect ratio" do
    scene = RingTracer.Scene.load!("priv/scenes/whitted.toml")
    {:ok, r} = RingTracer.render(scene, width: scene.width * 2, children: 1, atoms: 1, depth: 1)
    assert {r.width, r.height} == {scene.width * 2, scene.height * 2}

    {:ok, r} =
      RingTracer.render(scene, height: div(scene.height, 2), children: 1, atoms: 1, depth: 1)

    assert {r.width, r.height} == {div(scene.width, 2), div(scene.height, 2)}
  end

  test "a region holds exactly the whole render's pixels there, whatever the ring" do
    full = TestScenes.reference(@scene, 64, 48)

    expected =
      IO.iodata_to_binary(for y <- 5..29, do: binary_part(full, (y * 64 + 10) * 12, 30 * 12))

    for {strategy, n, k} <- [{:ring, 3, 4}, {:static, 1, 1}, {:steal, 4, 7}, {:master, 2, 3}] do
      {:ok, r} =
        RingTracer.render(TestScenes.path(@scene),
          width: 64,
          height: 48,
          region: {10, 5, 40, 30},
          strategy: strategy,
          children: n,
          atoms: k
        )

      assert {r.width, r.height} == {30, 25}
      assert r.pixels == expected, "#{strategy}"
    end

    {:ok, r} =
      RingTracer.render(TestScenes.path(@scene),
        width: 64,
        height: 48,
        region: {0.5, 0.0, 1.0, 0.5}
      )

    assert {r.width, r.height} == {32, 24}

    assert {:error, %RingTracer.Error{message: m}} =
             RingTracer.render(TestScenes.path(@scene),
               width: 64,
               height: 48,
               region: {10, 5, 90, 30}
             )

    assert m =~ "not inside the 64x48 image"
    assert {:error, _} = RingTracer.render(TestScenes.path(@scene), region: {5, 5, 5, 9})
  end
end
