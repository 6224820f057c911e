defmodule RingTracer.Scene do
  @moduledoc """
  A parsed scene: a handle on the kernel's scene and BVH, plus what is known
  about it.

  A handle (`:ref`) means something only on the node that parsed it. What
  travels between nodes is the `:source` (`RingTracer.Scene.Source`): the
  scene's bytes and the bytes of every file it references, with a content
  hash; each node parses it once (see `RingTracer.SceneCache`).

  Formats, by file extension: `.nff` (Eric Haines' Neutral File Format),
  `.toml` (RingTracer's own format, see `docs/scene-format.md`) and `.obj` (a Wavefront
  mesh with a default camera and light).

      iex> {:ok, scene} = RingTracer.Scene.load("priv/scenes/tetra_s1.nff")
      iex> {scene.width, scene.height, scene.lights}
      {512, 512, 1}
      iex> {:error, %RingTracer.Error{reason: :file}} = RingTracer.Scene.load("nope.nff")
  """

  alias RingTracer.{Error, Native}
  alias RingTracer.Scene.{Source, Warning}

  @enforce_keys [:ref, :source, :width, :height, :primitives, :lights]
  defstruct [
    :ref,
    :source,
    :width,
    :height,
    :primitives,
    :lights,
    frames: 1,
    path: nil,
    files: [],
    warnings: [],
    warnings_omitted: 0
  ]

  @typedoc """
  `:path` is the scene file (canonical, after symlinks) and `:files` every
  file it referenced, as read on this node; both empty for a scene parsed
  from a shipped source.

  `:warnings` are what parsed but may not render as meant (see
  `RingTracer.Scene.Warning`), the first 100 in the order found;
  `:warnings_omitted` counts the rest.
  """
  @type t :: %__MODULE__{
          ref: reference(),
          source: Source.t(),
          width: pos_integer(),
          height: pos_integer(),
          primitives: non_neg_integer(),
          lights: non_neg_integer(),
          frames: pos_integer(),
          path: Path.t() | nil,
          files: [Path.t()],
          warnings: [Warning.t()],
          warnings_omitted: non_neg_integer()
        }

  @formats %{".nff" => "nff", ".toml" => "toml", ".obj" => "obj"}

  @doc false
  # The image's size a render makes of `scene` given `:width` and `:height`
  # (either may be nil): one side given, the other follows the scene's
  # aspect ratio.
  @spec image_size(t(), pos_integer() | nil, pos_integer() | nil) ::
          {pos_integer(), pos_integer()}
  def image_size(scene, nil, nil), do: {scene.width, scene.height}
  def image_size(scene, w, nil), do: {w, max(1, round(w * scene.height / scene.width))}
  def image_size(scene, nil, h), do: {max(1, round(h * scene.width / scene.height)), h}
  def image_size(_scene, w, h), do: {w, h}

  @doc """
  Reads and parses the scene file at `path`.

  The scene file itself may be anywhere, but must be a regular file (not a
  FIFO, a device or a file of `/proc`) no larger than the kernel's file
  limit. Every file it references (TOML meshes, OBJ `mtllib`) is confined:
  after symlinks it must lie inside the scene file's folder or one of
  `:allow_dirs`, and be a regular file of bounded size, or the load fails
  with the scene's file and line and the reference as written. Nothing is
  read before these checks pass. The scene file's folder is opened once,
  when the scene file is read in it, and every reference is opened beneath
  that descriptor: swapping the folder, or one above it, for a symbolic
  link while the scene loads changes nothing.

  Input that cannot mean what it says (a second viewpoint, a `fov` of 200,
  a cone whose radii have opposite signs) is an error. Input that renders,
  but maybe not as meant (a zero-radius sphere, a colour above 1), loads
  with warnings in the scene's `:warnings`, each naming its file and line;
  nothing is printed or logged (see `RingTracer.Scene.Warning`).

      iex> {:ok, scene} = RingTracer.Scene.load("priv/scenes/balls_s1.nff")
      iex> scene.warnings
      []

  ## Options

    * `:allow_dirs` — more folders that referenced files may come from
      (default none)
  """
  @spec load(Path.t(), keyword()) :: {:ok, t()} | {:error, Error.t()}
  def load(path, opts \\ []) when is_binary(path) do
    allow = Enum.map(Keyword.get(opts, :allow_dirs) || [], &Path.expand/1)

    with {:ok, format} <- format_of(path),
         :ok <- check_dirs(allow),
         {:ok, bytes, real, dir} <- read(path) do
      # `dir`: the folder the scene file was read in, held open by the
      # kernel; its references are read beneath that very folder, never
      # looked up again by name
      with {:ok, scene} <-
             parse(bytes, format, Error.escape(Path.basename(path)), dir, allow, %{}),
           do: {:ok, %{scene | path: real}}
    end
  end

  @doc "Like `load/2` but raises `RingTracer.Error`."
  @spec load!(Path.t(), keyword()) :: t()
  def load!(path, opts \\ []) do
    case load(path, opts) do
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
    parse(source.bytes, source.format, source.name, nil, [], source.includes)
  end

  defp parse(bytes, format, name, scene_dir, allow, includes) do
    case Native.scene_parse(bytes, format, name, scene_dir, allow, includes) do
      {:ok, {ref, info, files, paths}} ->
        source = Source.new(name, format, bytes, Map.new(files))

        {:ok,
         %__MODULE__{
           ref: ref,
           source: source,
           width: info.width,
           height: info.height,
           primitives: info.primitives,
           lights: info.lights,
           frames: Native.scene_animation(ref).frames,
           files: paths,
           warnings: Enum.map(info.warnings, &Warning.from_native/1),
           warnings_omitted: info.warnings_omitted
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

  defp check_dirs(dirs) do
    case Enum.reject(dirs, &File.dir?/1) do
      [] -> :ok
      [dir | _] -> {:error, Error.new(:invalid_option, "--allow-dir #{dir}: no such folder")}
    end
  end

  defp read(path) do
    case Native.read_scene_file(Path.expand(path)) do
      {:ok, {bytes, real, dir}} -> {:ok, bytes, real, dir}
      # the kernel's message names the file
      {:error, message} -> {:error, Error.new(:file, message)}
    end
  end
end
