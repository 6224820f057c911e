defmodule Mix.Tasks.RingTracer.Render do
  @shortdoc "Renders a scene through the ring and writes an image"
  @moduledoc """
  Renders a scene file through a ring of children and writes the image:
  `ringtracer render` (`RingTracer.CLI.Render`) for Mix users.

      mix ring_tracer.render SCENE --out FILE [options]
      mix ring_tracer.render priv/scenes/whitted_orbit.toml --out frames/orbit_####.png

  Of an animated scene, a run of `#` in `--out` renders a sequence, one
  file per frame (`--frames A-B`, `--continue`). `mix ring_tracer.render
  --help` lists the options. A status other than 0
  (1 the render failed, 2 a usage error) ends Mix with that status. The
  scene's warnings go to stderr before the render, as
  `file:line: warning: message` (see `RingTracer.Scene.Warning`).
  """
  use Mix.Task

  @requirements ["app.config"]

  @impl Mix.Task
  def run(argv) do
    case RingTracer.CLI.Render.execute(argv) do
      :ok -> :ok
      {:error, status, message} -> Mix.raise(message, exit_status: status)
    end
  end
end
