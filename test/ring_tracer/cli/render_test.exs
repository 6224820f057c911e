defmodule RingTracer.CLI.RenderTest do
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO
  alias RingTracer.CLI.Render

  @moduletag :tmp_dir

  defp render(args) do
    me = self()

    out =
      capture_io(fn -> capture_io(:stderr, fn -> send(me, {:r, Render.execute(args)}) end) end)

    assert_received {:r, result}
    {result, out}
  end

  test "--region in pixels or fractions gives that part", %{tmp_dir: dir} do
    {:ok, out} =
      render(
        ~w(priv/scenes/balls_s2.nff -o #{dir}/a.png --width 64 --region 10,5,40,30 -q --progress none)
      )

    assert out == ""
    assert File.exists?(Path.join(dir, "a.png"))

    {:ok, out} =
      render(
        ~w(priv/scenes/balls_s2.nff -o #{dir}/b.png --width 64 --region 0.5,0,1,0.25 --progress none)
      )

    assert out =~ "b.png (32x16)"

    assert {{:error, 2, message}, _} =
             render(~w(priv/scenes/balls_s2.nff -o #{dir}/c.png --region 1,2,3))

    assert message =~ "--region takes X0,Y0,X1,Y1"
  end

  test "values out of range and bad choices are usage errors that say what is accepted", %{
    tmp_dir: dir
  } do
    for {args, text} <- [
          {~w(--samples 17), "--samples takes an integer from 1 to 16, got: 17"},
          {~w(--strategy ringg), "--strategy takes one of"},
          {~w(--speeds 1,0.5), "--speeds takes numbers from 1 to 1000"},
          {~w(--speeds 1,,1), "--speeds takes numbers from 1 to 1000"},
          # refused by the render itself, before any work: still usage errors, in the CLI's words
          {~w(--children 2 --atoms 1048576), "--children x --atoms must be at most 1048576"},
          {~w(--region 10,10,5000,5000), "is not inside the"},
          {~w(--cutoff -1), "--cutoff takes a number from 0"},
          {~w(--progress loud), "--progress takes bar, log or none"}
        ] do
      assert {{:error, 2, message}, _} =
               render(~w(priv/scenes/balls_s2.nff -o #{dir}/x.png) ++ args)

      assert message =~ text
    end

    refute File.exists?(Path.join(dir, "x.png"))
  end

  test "--frame renders that frame of an animated scene; past the last it is a usage error", %{
    tmp_dir: dir
  } do
    scene = "priv/scenes/whitted_orbit.toml"
    args = ~w(--width 32 --children 2 -q --progress none)
    {:ok, ""} = render(~w(#{scene} -o #{dir}/f1.png) ++ args)
    {:ok, ""} = render(~w(#{scene} -o #{dir}/f7.png --frame 7) ++ args)
    assert File.read!(Path.join(dir, "f1.png")) != File.read!(Path.join(dir, "f7.png"))

    assert {{:error, 2, message}, _} = render(~w(#{scene} -o #{dir}/f0.png --frame 0) ++ args)
    assert message =~ "--frame takes an integer from 1"

    assert {{:error, 2, message}, _} = render(~w(#{scene} -o #{dir}/f49.png --frame 49) ++ args)
    assert message =~ "frame must be at most 48 (the frames of whitted_orbit.toml), got: 49"
    refute File.exists?(Path.join(dir, "f49.png"))
  end
end
