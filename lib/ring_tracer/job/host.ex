defmodule RingTracer.Job.Host do
  @moduledoc false
  # A job's start on one node, in one call from the parent: the node checks
  # that it can host the job's children (the application runs, the NIF is
  # loaded, the parent runs the same build), pins the job's scene for the
  # parent's lifetime (`RingTracer.Kernel`'s `prepare_node/3`) and starts
  # the children it is given. The parent makes this call to every node at
  # once (`RingTracer.Job.Start`).
  #
  # The request carries the scene by hash only; a node that does not hold
  # it answers `:need_scene`, and the parent asks again with the scene
  # packed (`RingTracer.Scene.Source.pack/1`): at most two round trips, and
  # the scene's bytes only to the nodes that lack it.

  alias RingTracer.Cluster.Build
  alias RingTracer.Job.{Child, Spec}

  @enforce_keys [:build, :parent, :spec, :children]
  defstruct @enforce_keys

  @typedoc """
  What the parent asks of a node: its build, its pid (the owner of the
  scene's pin and of the children), the children's spec (the scene by hash,
  or packed) and the children to start there, each an index and a speed.
  """
  @type t :: %__MODULE__{
          build: Build.t(),
          parent: pid(),
          spec: Spec.t(),
          children: [{non_neg_integer(), number()}]
        }

  @typedoc """
  The node's answer: the children started (index and pid); `:need_scene`
  when it does not hold the job's scene; `{:build, theirs}` when the
  parent's build is not this node's (the parent names both); or an error
  with its reason.
  """
  @type reply ::
          {:ok, [{non_neg_integer(), pid()}]}
          | :need_scene
          | {:build, Build.t()}
          | {:error, {atom(), String.t()}}

  @doc false
  @spec start(t()) :: reply()
  def start(%__MODULE__{} = request) do
    with :ok <- check(request.build),
         :ok <- prepare(request) do
      start_children(request)
    end
  end

  @doc false
  # Whether this node can host children of a node of build `build`: it
  # runs the application, has loaded the NIF, and runs that build
  # (`RingTracer.Cluster.check/1` asks this alone).
  @spec check(Build.t()) :: :ok | {:build, Build.t()} | {:error, {atom(), String.t()}}
  def check(build) do
    with :ok <- running(), do: same_build(build)
  end

  defp running do
    cond do
      Process.whereis(RingTracer.Supervisor) == nil ->
        {:error,
         {:node_unavailable,
          "node #{node()} does not run :ring_tracer; start it with mix ring_tracer.worker"}}

      not is_integer(nif_count()) ->
        {:error, {:node_unavailable, "node #{node()} has not loaded RingTracer's NIF"}}

      true ->
        :ok
    end
  end

  defp nif_count do
    RingTracer.Native.scene_live_count()
  rescue
    _ -> nil
  end

  defp same_build(build) do
    case Build.identity() do
      ^build -> :ok
      ours -> {:build, ours}
    end
  end

  defp prepare(%__MODULE__{spec: %Spec{kernel: {kernel, opts}} = spec, parent: parent}) do
    case kernel.prepare_node(spec, opts, parent) do
      :ok -> :ok
      :need_scene -> :need_scene
      {:error, message} -> {:error, {:invalid_scene, "#{node()}: #{message}"}}
    end
  end

  defp start_children(%__MODULE__{spec: spec, parent: parent, children: children}) do
    Enum.reduce_while(children, {:ok, []}, fn {i, speed}, {:ok, acc} ->
      case Child.start(node(), %{spec | speeds: [speed]}, i, parent) do
        {:ok, pid} ->
          {:cont, {:ok, [{i, pid} | acc]}}

        other ->
          for {_, pid} <- acc, do: Process.exit(pid, :kill)

          {:halt,
           {:error,
            {:node_unavailable, "could not start child #{i} on #{node()}: #{inspect(other)}"}}}
      end
    end)
    |> case do
      {:ok, started} -> {:ok, Enum.reverse(started)}
      error -> error
    end
  end
end
