defmodule RingTracer.Kernel.Native do
  @moduledoc """
  The Rust kernel through the NIF: traces on a dirty CPU scheduler (an atom
  of a few pixels first on the grandchild's own scheduler, for at most
  200 µs) with the scene parsed once per node and pinned there while the job
  runs (`RingTracer.SceneCache`). A panic or error in
  the kernel comes back as `{:error, message}`, never as a crash of the VM.
  """
  @behaviour RingTracer.Kernel

  alias RingTracer.{Layout, Native, Rays, SceneCache, Settings}

  # Pixels of the preview that `atom_work/2` traces (about 0.1% of a
  # 1024x1024 image), and at most this share of a small image's.
  @preview_pixels 1024
  # How long a node may take to parse and pin a job's scene (a node that
  # freezes meanwhile is disconnected sooner, by the job's liveness watch).
  @prepare_ms 60_000
  @preview_share 1 / 64
  # An atom of at most this many pixels is traced on the grandchild's own
  # scheduler for at most @short_budget_us, and only what is left over on a
  # dirty one: a dirty call's two scheduler switches cost more than a few
  # cheap pixels take to trace.
  @short_pixels 256
  @short_budget_us 200

  @impl RingTracer.Kernel
  def prepare(spec, _opts) do
    with {:ok, scene} <- frame_scene(spec), do: {:ok, {scene, Settings.to_native(spec.settings)}}
  end

  # The scene of the job's frame: the cached scene is its first frame; any
  # other is made from it (sharing its geometry where only the camera,
  # lights, colours or meshes move).
  defp frame_scene(spec) do
    case SceneCache.fetch(spec.source) do
      {:ok, scene} when spec.frames == [0] ->
        {:ok, scene}

      {:ok, scene} ->
        case Native.scene_frame(scene.ref, hd(spec.frames)) do
          {:ok, ref} -> {:ok, %{scene | ref: ref}}
          {:error, message} -> {:error, message}
        end

      {:error, error} ->
        {:error, error.message}
    end
  end

  @impl RingTracer.Kernel
  # The parent pins the scene on each node for as long as it lives, so no
  # other job's scenes can push it out of a cache while this job runs.
  def prepare_node(spec, _opts, node) when node == node() do
    with :ok <- SceneCache.pin(spec.source, self()), do: {:ok, 0}
  end

  def prepare_node(spec, _opts, node) do
    case :erpc.call(node, SceneCache, :pin, [spec.source, self()], @prepare_ms) do
      :ok -> {:ok, RingTracer.Scene.Source.size(spec.source)}
      {:error, message} -> {:error, "#{node}: #{message}"}
    end
  rescue
    e in ErlangError ->
      case e.original do
        {:erpc, _} -> {:error, RingTracer.Cluster.call_failure(node, e.original, @prepare_ms)}
        _ -> {:error, "#{node}: #{Exception.message(e)}"}
      end
  end

  @doc """
  Each atom's work, estimated from a preview: the same scene and settings
  traced at about #{@preview_pixels} pixels (`preview_size/2`) in one kernel
  call, each image row taking the work of the preview row it falls in.
  """
  @impl RingTracer.Kernel
  def atom_work(%{settings: %Settings{region: region}}, _opts) when region != nil,
    do: {:error, "no preview of a region"}

  def atom_work(%{settings: %Settings{width: w, height: h} = settings} = spec, opts) do
    {pw, ph} = preview_size(w, h)
    preview = Settings.to_native(%{settings | width: pw, height: ph})

    with {:ok, {scene, _}} <- prepare(spec, opts),
         {:ok, rows} <- Native.row_work(scene.ref, preview) do
      rows = List.to_tuple(rows)
      per_row = List.to_tuple(for r <- 0..(h - 1), do: elem(rows, div(r * ph, h)) * w / pw)
      {:ok, Layout.work_by_atom(spec.layout, per_row)}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
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
  def trace({scene, native}, first, count, _atom) when count <= @short_pixels do
    case Native.trace_atom_short(scene.ref, native, first, count, @short_budget_us) do
      {:ok, {pixels, rays, us, ^count}} ->
        {:ok, pixels, rays, us}

      {:ok, {head, head_rays, head_us, done}} ->
        with {:ok, {pixels, rays, us}} <-
               Native.trace_atom(scene.ref, native, first + done, count - done) do
          {:ok, head <> pixels, Rays.add(head_rays, rays), head_us + us}
        end

      {:error, message} ->
        {:error, message}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end

  def trace({scene, native}, first, count, _atom) do
    case Native.trace_atom(scene.ref, native, first, count) do
      {:ok, {pixels, rays, us}} -> {:ok, pixels, rays, us}
      {:error, message} -> {:error, message}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end
end
