defmodule RingTracer.Scene do
  @moduledoc """
  A parsed scene: a handle on the kernel's scene and BVH, plus what is known
  about it.

  A handle (`:ref`) means something only on the node that parsed it. What
  travels between nodes is the `:source` (`RingTracer.Scene.Source`): the
  scene's bytes and the bytes of every file it references, with a content
  hash; each node parses it once (see `RingTracer.SceneCache`).

  Formats, by file extension: `.nff` (Eric Haines' Neutral File Format),
  `.toml` (RingTracer's own format, see the README) and `.obj` (a Wavefront
  mesh with a default camera and light).

      iex> {:ok, scene} = RingTracer.Scene.load("priv/scenes/tetra_s1.nff")
      iex> {scene.width, scene.height, scene.lights}
      {512, 512, 1}
      iex> {:error, %RingTracer.Error{reason: :file}} = RingTracer.Scene.load("nope.nff")
  """

  alias RingTracer.{Error, Native}
  alias RingTracer.Scene.Source

  @enforce_keys [:ref, :source, :width, :height, :primitives, :lights]
  defstruct [:ref, :source, :width, :height, :primitives, :lights]

  @type t :: %__MODULE__{
          ref: reference(),
          source: Source.t(),
          width: pos_integer(),
          height: pos_integer(),
          primitives: non_neg_integer(),
          lights: non_neg_integer()
        }

  @formats %{".nff" => "nff", ".toml" => "toml", ".obj" => "obj"}

  @doc """
  Reads and parses the scene file at `path`; referenced files (meshes) are
  read relative to its directory.
  """
  @spec load(Path.t()) :: {:ok, t()} | {:error, Error.t()}
  def load(path) when is_binary(path) do
    with {:ok, format} <- format_of(path),
         {:ok, bytes} <- read(path) do
      parse(bytes, format, Path.basename(path), Path.dirname(Path.expand(path)), %{})
    end
  end

  @doc "Like `load/1` but raises `RingTracer.Error`."
  @spec load!(Path.t()) :: t()
  def load!(path) do
    case load(path) do
      {:ok, scene} -> scene
      {:error, error} -> raise error
    end
  end

  @doc """
  Parses a scene from its shipped source, on this node. Nothing is read from
  disk: referenced files must be in the source's includes.
  """
  @spec from_source(Source.t()) :: {:ok, t()} | {:error, Error.t()}
  def from_source(%Source{} = source) do
    parse(source.bytes, source.format, source.name, nil, source.includes)
  end

  defp parse(bytes, format, name, base_dir, includes) do
    case Native.scene_parse(bytes, format, name, base_dir, [], includes) do
      {:ok, {ref, info, files, _read_paths}} ->
        source = Source.new(name, format, bytes, Map.new(files))

        {:ok,
         %__MODULE__{
           ref: ref,
           source: source,
           width: info.width,
           height: info.height,
           primitives: info.primitives,
           lights: info.lights
         }}

      {:error, message} ->
        {:error, Error.new(:invalid_scene, message)}
    end
  end

  defp format_of(path) do
    case Map.fetch(@formats, String.downcase(Path.extname(path))) do
      {:ok, format} ->
        {:ok, format}

      :error ->
        {:error,
         Error.new(
           :invalid_scene,
           "#{path}: unknown scene format #{inspect(Path.extname(path))}; expected .nff, .toml or .obj"
         )}
    end
  end

  defp read(path) do
    case File.read(path) do
      {:ok, bytes} -> {:ok, bytes}
      {:error, reason} -> {:error, Error.new(:file, "#{path}: #{:file.format_error(reason)}")}
    end
  end
end
