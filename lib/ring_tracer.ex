defmodule RingTracer do
  @moduledoc """
  RingTracer renders one image with many BEAM processes, possibly on many
  nodes, balanced by the ring model of Câmara and Guedes: a parent, N
  children linked in a ring, one grandchild per child tracing one atom at a
  time in a native Whitted ray tracer.

      iex> {:ok, result} = RingTracer.render("priv/scenes/tetra_s1.nff", children: 3, atoms: 4, width: 32, height: 24)
      iex> byte_size(result.pixels)
      32 * 24 * 12
      iex> Enum.sum(Enum.map(result.children, & &1.traced))
      12

  See `render/2` for the options and `RingTracer.Image` to write files.
  """

  alias RingTracer.{Error, Layout, Native, Options, Result, Scene, SceneCache, Settings}
  alias RingTracer.Job.{Parent, Spec}

  @doc """
  Renders the scene file at `path` (`.nff`, `.toml` or `.obj`) and returns the
  image and the job's statistics.

  ## Options

    * `:children` — ring size N (default: schedulers online)
    * `:atoms` — atoms per child K (default 16)
    * `:width`, `:height` — image size (default: the scene's)
    * `:depth` — ray-tree depth limit, eye ray = 1 (default 5)
    * `:cutoff` — adaptive cut-off: a branch whose weight falls below it is
      not traced (default 1/255; 0 disables)
    * `:samples` — S x S stratified samples per pixel (default 1)
    * `:spd` — SPD testing procedure: rays through pixel corners, no
      cut-off (default false)
    * `:nodes` — nodes to place children on, round robin (default: this node)
    * `:timeout` — milliseconds, or `:infinity` (default)

  Returns `{:ok, %RingTracer.Result{}}` or `{:error, %RingTracer.Error{}}`
  for a missing or invalid scene, a bad option, or a job that failed.
  """
  @spec render(Path.t(), keyword()) :: {:ok, Result.t()} | {:error, Error.t()}
  def render(path, opts \\ []) when is_binary(path) do
    with {:ok, opts} <- Options.validate(opts),
         {:ok, scene} <- Scene.load(path),
         {:ok, settings} <- settings(scene, opts) do
      :ok = SceneCache.put(scene)
      run(scene, settings, opts)
    end
  end

  @doc "Like `render/2` but returns the result or raises `RingTracer.Error`."
  @spec render!(Path.t(), keyword()) :: Result.t()
  def render!(path, opts \\ []) do
    case render(path, opts) do
      {:ok, result} -> result
      {:error, error} -> raise error
    end
  end

  @doc """
  The settings a render of `scene` with `opts` (already validated) uses.
  """
  @spec settings(Scene.t(), keyword()) :: {:ok, Settings.t()} | {:error, Error.t()}
  def settings(%Scene{} = scene, opts) do
    settings = %Settings{
      width: opts[:width] || scene.width,
      height: opts[:height] || scene.height,
      depth: opts[:depth],
      cutoff: opts[:cutoff] / 1,
      samples: opts[:samples],
      spd: opts[:spd]
    }

    case Native.validate_settings(Settings.to_native(settings)) do
      {:ok, true} -> {:ok, settings}
      {:error, message} -> {:error, Error.new(:invalid_option, message)}
    end
  end

  defp run(scene, settings, opts) do
    spec = %Spec{
      id: make_ref(),
      source: scene.source,
      settings: settings,
      layout: Layout.new(settings.width, settings.height, opts[:children], opts[:atoms]),
      caller: self(),
      nodes: opts[:nodes],
      handover_delay: opts[:handover_delay]
    }

    {:ok, parent} = Parent.start(spec)
    ref = Process.monitor(parent)

    receive do
      {RingTracer, id, reply} when id == spec.id ->
        receive do
          {:DOWN, ^ref, _, _, _} -> :ok
        end

        case reply do
          {:ok, raw} -> {:ok, Result.new(settings, raw)}
          {:error, message} -> {:error, Error.new(:render_failed, message)}
        end

      {:DOWN, ^ref, _, _, reason} ->
        {:error, Error.new(:render_failed, "the job's parent exited: #{inspect(reason)}")}
    after
      opts[:timeout] ->
        Process.demonitor(ref, [:flush])
        DynamicSupervisor.terminate_child(RingTracer.Names.jobs(), parent)
        {:error, Error.new(:render_failed, "timed out after #{opts[:timeout]} ms")}
    end
  end
end
