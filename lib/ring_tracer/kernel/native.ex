defmodule RingTracer.Kernel.Native do
  @moduledoc false
  # The Rust kernel through the NIF: traces on a dirty CPU scheduler (an atom
  # of a few pixels first on the grandchild's own scheduler, for at most
  # 200 µs) with the scene parsed once per node and pinned there while the job
  # runs (`RingTracer.SceneCache`). A panic or error in
  # the kernel comes back as `{:error, message}`, never as a crash of the VM.
  #
  # A job of several frames (`RingTracer.Layout`, "Frames") traces each atom
  # in the scene of its frame: the node's cache builds each frame once
  # (`RingTracer.SceneCache.fetch_frame/2`), and a grandchild keeps the last
  # frame it traced (in its process dictionary), so that it looks a frame up
  # only when it moves on to another.
  @behaviour RingTracer.Kernel

  alias RingTracer.{Layout, Native, Rays, SceneCache, Settings}
  alias RingTracer.Scene.Source

  defmodule Frames do
    @moduledoc false
    # The context of a job of several frames: the scene's source, the
    # layout's atoms per frame, and the scene's frame for each of the
    # layout's (`RingTracer.Job.Spec`'s `frames`, as a tuple).
    @enforce_keys [:source, :frame_atoms, :frames, :native]
    defstruct @enforce_keys

    @type t :: %__MODULE__{
            source: RingTracer.Scene.Source.t(),
            frame_atoms: pos_integer(),
            frames: tuple(),
            native: term()
          }
  end

  # Where a grandchild keeps the last frame it traced: {hash, frame, ref}.
  @last_frame {__MODULE__, :last_frame}

  # Pixels of the preview that `atom_work/2` traces (about 0.1% of a
  # 1024x1024 image), and at most this share of a small image's.
  @preview_pixels 1024
  @preview_share 1 / 64
  # An atom of at most this many pixels is traced on the grandchild's own
  # scheduler for at most @short_budget_us, and only what is left over on a
  # dirty one: a dirty call's two scheduler switches cost more than a few
  # cheap pixels take to trace.
  @short_pixels 256
  @short_budget_us 200

  @impl RingTracer.Kernel
  def prepare(%{layout: %Layout{frames: 1}, frames: [frame]} = spec, _opts) do
    with {:ok, scene} <- frame_scene(spec.source, frame),
         do: {:ok, {scene, Settings.to_native(spec.settings)}}
  end

  def prepare(spec, _opts) do
    with {:ok, _scene} <- check_frames(spec) do
      {:ok,
       %Frames{
         source: spec.source,
         frame_atoms: Layout.frame_atom_count(spec.layout),
         frames: List.to_tuple(spec.frames),
         native: Settings.to_native(spec.settings)
       }}
    end
  end

  # The scene of frame `frame`: the cached scene is its first frame; any
  # other is made from it once per node (sharing its geometry where only
  # the camera, lights, colours or meshes move).
  defp frame_scene(source, frame) do
    with {:ok, scene} <- fetch(source) do
      case frame do
        0 ->
          {:ok, scene}

        _ ->
          case SceneCache.fetch_frame(source, frame) do
            {:ok, ref} -> {:ok, %{scene | ref: ref}}
            {:error, error} -> {:error, error.message}
          end
      end
    end
  end

  defp fetch(source) do
    case SceneCache.fetch(source) do
      {:ok, scene} -> {:ok, scene}
      {:error, error} -> {:error, error.message}
    end
  end

  # The spec's frames, one per layout frame, are all frames of the scene.
  defp check_frames(%{source: source, layout: layout, frames: frames}) do
    with {:ok, scene} <- fetch(source) do
      cond do
        length(frames) != layout.frames ->
          {:error,
           "the job lists #{length(frames)} scene frame(s) for a layout of #{layout.frames}"}

        bad = Enum.find(frames, &(not (is_integer(&1) and &1 in 0..(scene.frames - 1)))) ->
          {:error,
           "scene #{source.name} has #{scene.frames} frame(s) (0 to #{scene.frames - 1}): " <>
             "no frame #{inspect(bad)}"}

        true ->
          {:ok, scene}
      end
    end
  end

  # The handle of the scene of `atom`'s frame: the last one this process
  # traced, or the node's cache's.
  defp frame_ref(%Frames{source: %Source{hash: hash} = source} = context, atom) do
    index = div(Layout.base(atom), context.frame_atoms)

    if index < tuple_size(context.frames) do
      frame = elem(context.frames, index)

      case Process.get(@last_frame) do
        {^hash, ^frame, ref} ->
          {:ok, ref}

        _ ->
          case SceneCache.fetch_frame(source, frame) do
            {:ok, ref} ->
              Process.put(@last_frame, {hash, frame, ref})
              {:ok, ref}

            {:error, error} ->
              {:error, error.message}
          end
      end
    else
      {:error, "atom #{Layout.name(atom)} is past the job's #{tuple_size(context.frames)} frames"}
    end
  end

  @impl RingTracer.Kernel
  # The parent pins the scene on each node for as long as it lives, so no
  # other job's scenes can push it out of a cache while this job runs.
  def prepare_node(spec, _opts, owner), do: SceneCache.pin(spec.source, owner)

  @doc """
  Each atom's work, estimated from a preview: the same scene and settings
  traced at about #{@preview_pixels} pixels (`preview_size/2`) in one kernel
  call, each image row taking the work of the preview row it falls in. In a
  job of several frames, the atoms of one frame, previewed in the first
  frame listed.
  """
  @impl RingTracer.Kernel
  def atom_work(%{settings: %Settings{region: region}}, _opts) when region != nil,
    do: {:error, "no preview of a region"}

  def atom_work(%{settings: %Settings{width: w, height: h} = settings} = spec, opts) do
    {pw, ph} = preview_size(w, h)
    preview = Settings.to_native(%{settings | width: pw, height: ph})

    with {:ok, scene} <- first_scene(spec, opts),
         {:ok, rows} <- Native.row_work(scene.ref, preview) do
      rows = List.to_tuple(rows)
      per_row = List.to_tuple(for r <- 0..(h - 1), do: elem(rows, div(r * ph, h)) * w / pw)
      {:ok, Layout.work_by_atom(spec.layout, per_row)}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end

  # The scene of the job's first frame.
  defp first_scene(%{layout: %Layout{frames: 1}} = spec, opts) do
    with {:ok, {scene, _}} <- prepare(spec, opts), do: {:ok, scene}
  end

  defp first_scene(spec, _opts) do
    with {:ok, _} <- check_frames(spec), do: frame_scene(spec.source, hd(spec.frames))
  end

  @doc """
  The size of the preview `atom_work/2` traces for a `w` x `h` image: about
  #{@preview_pixels} pixels, and at most 1/64 of the image's own, so that on a
  small image (a short job) the preview does not cost a large share of
  the job's tracing (at 64x64, #{@preview_pixels} pixels would be a quarter of it).

      iex> RingTracer.Kernel.Native.preview_size(1024, 1024)
      {32, 32}
      iex> RingTracer.Kernel.Native.preview_size(256, 128)
      {32, 16}
      iex> RingTracer.Kernel.Native.preview_size(64, 64)
      {8, 8}
      iex> RingTracer.Kernel.Native.preview_size(4, 4)
      {1, 1}
  """
  @spec preview_size(pos_integer(), pos_integer()) :: {pos_integer(), pos_integer()}
  def preview_size(w, h) do
    scale = max(:math.sqrt(1 / @preview_share), :math.sqrt(w * h / @preview_pixels))
    {max(1, round(w / scale)), max(1, round(h / scale))}
  end

  @impl RingTracer.Kernel
  def trace(%Frames{} = context, first, count, atom) do
    case frame_ref(context, atom) do
      {:ok, ref} -> trace_in(ref, context.native, first, count)
      {:error, message} -> {:error, message}
    end
  end

  def trace({scene, native}, first, count, _atom), do: trace_in(scene.ref, native, first, count)

  defp trace_in(ref, native, first, count) when count <= @short_pixels do
    case Native.trace_atom_short(ref, native, first, count, @short_budget_us) do
      {:ok, {pixels, rays, us, ^count}} ->
        {:ok, pixels, rays, us}

      {:ok, {head, head_rays, head_us, done}} ->
        with {:ok, {pixels, rays, us}} <-
               Native.trace_atom(ref, native, first + done, count - done) do
          {:ok, head <> pixels, Rays.add(head_rays, rays), head_us + us}
        end

      {:error, message} ->
        {:error, message}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end

  defp trace_in(ref, native, first, count) do
    case Native.trace_atom(ref, native, first, count) do
      {:ok, {pixels, rays, us}} -> {:ok, pixels, rays, us}
      {:error, message} -> {:error, message}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end
end
