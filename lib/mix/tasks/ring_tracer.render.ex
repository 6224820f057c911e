defmodule Mix.Tasks.RingTracer.Render do
  @shortdoc "Renders a scene through the ring and writes an image"
  @moduledoc """
  Renders a scene file through a ring of children and writes the image.

      mix ring_tracer.render SCENE --out FILE [options]

  `FILE` ends in `.png` (8-bit sRGB) or `.exr` (linear float).

  ## Options

    * `--out FILE` — where to write the image (required)
    * `--children N` — ring size (default: schedulers online)
    * `--atoms K` — atoms per child (default 16)
    * `--width W`, `--height H` — image size (default: the scene's)
    * `--depth D` — ray-tree depth limit, eye ray = 1 (default 5)
    * `--cutoff C` — adaptive cut-off weight (default 1/255, 0 disables)
    * `--samples S` — S x S samples per pixel (default 1)
    * `--spd` — the SPD testing procedure (pixel corners, no cut-off)

  Prints where it wrote the image, the job's time, the ray counts and a line
  per child.
  """
  use Mix.Task

  @switches [
    out: :string,
    children: :integer,
    atoms: :integer,
    width: :integer,
    height: :integer,
    depth: :integer,
    cutoff: :float,
    samples: :integer,
    spd: :boolean
  ]

  @impl Mix.Task
  def run(argv) do
    {opts, args, invalid} = OptionParser.parse(argv, strict: @switches, aliases: [o: :out])

    if invalid != [] do
      Mix.raise("invalid option(s): #{Enum.map_join(invalid, ", ", &elem(&1, 0))}")
    end

    scene =
      case args do
        [scene] -> scene
        _ -> Mix.raise("usage: mix ring_tracer.render SCENE --out FILE [options]")
      end

    out = opts[:out] || Mix.raise("--out FILE is required (a .png or .exr file)")
    Mix.Task.run("app.start")

    render_opts = Keyword.drop(opts, [:out])

    with {:ok, result} <- RingTracer.render(scene, render_opts),
         :ok <- RingTracer.Image.write(result, out) do
      report(out, result)
    else
      {:error, %RingTracer.Error{message: message}} -> Mix.raise(message)
    end
  end

  defp report(out, result) do
    r = result.rays

    Mix.shell().info(
      "wrote #{out} (#{result.width}x#{result.height}) in #{format_ms(result.elapsed_us)} " <>
        "with #{length(result.children)} children"
    )

    Mix.shell().info(
      "rays: eye #{r.eye} (hit #{r.eye_hits}), reflected #{r.reflected}, " <>
        "refracted #{r.refracted}, shadow #{r.shadow}"
    )

    for c <- result.children do
      Mix.shell().info(
        "  child #{c.index}: own #{c.own} given #{c.given} received #{c.received} " <>
          "traced #{c.traced}; offers sent #{c.offers_sent} passed #{c.offers_passed} " <>
          "consumed #{c.offers_consumed}"
      )
    end
  end

  defp format_ms(us), do: :io_lib.format("~.3f s", [us / 1_000_000]) |> IO.iodata_to_binary()
end
