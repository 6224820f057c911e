defmodule RingTracer.Chaos.Farm.References do
  @moduledoc false
  # What each frame of the farm soak must be: the SHA-256 of the file (PNG or
  # EXR) of that frame rendered alone on this node (`RingTracer.render/2`, no
  # farm, no faults), computed once per scene, frame and format.

  alias RingTracer.Chaos
  alias RingTracer.Chaos.Farm.Schedule

  @typedoc "A frame's key: scene, frame number (from 1) and format."
  @type key :: {String.t(), pos_integer(), :png | :exr}

  @doc "The hashes of every frame of the schedule's jobs, at `width` x `height`."
  @spec hashes(Schedule.t(), pos_integer(), pos_integer()) ::
          {:ok, %{key() => binary()}} | {:error, RingTracer.Error.t()}
  def hashes(%Schedule{jobs: jobs}, width, height) do
    dir =
      Path.join(
        System.tmp_dir!(),
        "rt_farm_refs_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}"
      )

    File.mkdir_p!(dir)

    try do
      jobs
      |> Enum.flat_map(fn job -> Enum.map(job.frames, &{job.scene, &1, job.format}) end)
      |> Enum.uniq()
      |> Enum.reduce_while({:ok, %{}}, fn key, {:ok, acc} ->
        case hash(key, width, height, dir) do
          {:ok, h} -> {:cont, {:ok, Map.put(acc, key, h)}}
          {:error, _} = error -> {:halt, error}
        end
      end)
    after
      File.rm_rf!(dir)
    end
  end

  @doc "The SHA-256 of a file's bytes."
  @spec sha(binary()) :: binary()
  def sha(bytes), do: :crypto.hash(:sha256, bytes)

  defp hash({scene, frame, format}, width, height, dir) do
    path = Chaos.scene_path(scene)
    out = Path.join(dir, "ref.#{format}")

    with {:ok, result} <- RingTracer.render(path, frame: frame, width: width, height: height),
         :ok <- RingTracer.Image.write(result, out) do
      {:ok, sha(File.read!(out))}
    end
  end
end
