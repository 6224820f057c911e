defmodule RingTracer.TestScenes do
  @moduledoc "Scenes and references shared by the tests."

  alias RingTracer.{Native, Scene, Settings}

  @doc "Absolute path of a scene in priv/scenes."
  @spec path(String.t()) :: String.t()
  def path(name), do: Path.expand(Path.join(["priv", "scenes", name]))

  @doc """
  The single-process reference image: the kernel's own whole-image render
  (of frame `:frame` of an animated scene, from 1).
  """
  @spec reference(String.t(), pos_integer(), pos_integer(), keyword()) :: binary()
  def reference(name, width, height, opts \\ []) do
    scene = Scene.load!(path(name))
    {frame, opts} = Keyword.pop(opts, :frame, 1)

    ref =
      if frame == 1,
        do: scene.ref,
        else: elem(Native.scene_frame(scene.ref, frame - 1), 1)

    settings = struct(%Settings{width: width, height: height}, opts)
    {:ok, {pixels, _rays}} = Native.render_image(ref, Settings.to_native(settings), 1)
    pixels
  end

  @doc "Every child process currently alive on this node, of any job."
  @spec children() :: [pid()]
  def children do
    for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Children),
        is_pid(pid),
        do: pid
  end

  @doc "Writes a scene file with `contents` to a temporary directory and returns its path."
  @spec tmp_scene(String.t(), String.t()) :: String.t()
  def tmp_scene(name, contents) do
    dir =
      Path.join(
        System.tmp_dir!(),
        "ring_tracer_test_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}"
      )

    File.mkdir_p!(dir)
    path = Path.join(dir, name)
    File.write!(path, contents)
    path
  end
end
