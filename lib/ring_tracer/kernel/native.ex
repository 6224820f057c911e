defmodule RingTracer.Kernel.Native do
  @moduledoc """
  The Rust kernel through the NIF: traces on a dirty CPU scheduler with the
  scene parsed once per node (`RingTracer.SceneCache`). A panic or error in
  the kernel comes back as `{:error, message}`, never as a crash of the VM.
  """
  @behaviour RingTracer.Kernel

  alias RingTracer.{Native, SceneCache, Settings}

  @impl RingTracer.Kernel
  def prepare(spec, _opts) do
    case SceneCache.fetch(spec.source) do
      {:ok, scene} -> {:ok, {scene, Settings.to_native(spec.settings)}}
      {:error, error} -> {:error, error.message}
    end
  end

  @impl RingTracer.Kernel
  def prepare_node(spec, _opts, node) when node == node() do
    with :ok <- SceneCache.preload(spec.source), do: {:ok, 0}
  end

  def prepare_node(spec, _opts, node) do
    case :erpc.call(node, SceneCache, :preload, [spec.source], 60_000) do
      :ok -> {:ok, RingTracer.Scene.Source.size(spec.source)}
      {:error, message} -> {:error, "#{node}: #{message}"}
    end
  rescue
    e in ErlangError -> {:error, "#{node}: #{Exception.message(e)}"}
  end

  @impl RingTracer.Kernel
  def trace({scene, native}, first, count, _atom) do
    case Native.trace_atom(scene.ref, native, first, count) do
      {:ok, {pixels, rays, us}} -> {:ok, pixels, rays, us}
      {:error, message} -> {:error, message}
    end
  rescue
    e in ErlangError -> {:error, "kernel raised: #{Exception.message(e)}"}
  end
end
