defmodule RingTracer.Job.Start do
  @moduledoc false
  # The parent's side of starting a job's children on their nodes
  # (`RingTracer.Job.Host` is the nodes' side): one request to every node
  # at once, carrying the scene by its hash; a second, with the scene
  # packed, only to the nodes that answered that they lack it. So a job
  # starts in one round trip to nodes that hold its scene and two to those
  # that do not, whatever the number of nodes.

  alias RingTracer.Cluster
  alias RingTracer.Cluster.Build
  alias RingTracer.Job.{Host, Spec}
  alias RingTracer.Scene.Source

  # How long a node may take to answer the first request (its checks, the
  # scene pinned if it holds it, its children started): this, plus a
  # little per child it starts.
  @check_ms 5_000
  @per_child_ms 2
  # ... and the second, with a scene to unpack and parse.
  @prepare_ms 60_000

  @typedoc "The children to start on each node: index and speed."
  @type plan :: %{node() => [{non_neg_integer(), number()}]}

  @typedoc """
  The children started (index and pid) and the scene's bytes sent to each
  node; or an error's reason and message, with the children started on
  the nodes that answered (for the parent to stop).
  """
  @type outcome ::
          {:ok, [{non_neg_integer(), pid()}], %{node() => non_neg_integer()}}
          | {:error, atom(), String.t(), [{non_neg_integer(), pid()}]}

  @doc false
  @spec run(Spec.t(), plan()) :: outcome()
  def run(%Spec{} = spec, plan) do
    base = %{spec | source: Source.strip(spec.source), nodes: [], speeds: []}
    request = %Host{build: Build.identity(), parent: self(), spec: base, children: []}
    nodes = Map.keys(plan)

    first =
      ask(nodes, fn node ->
        {%{request | children: plan[node]}, @check_ms + @per_child_ms * length(plan[node])}
      end)

    case for {node, :need_scene} <- first, do: node do
      [] ->
        outcome(nodes, first, %{})

      lacking ->
        packed = %{base | source: Source.pack(spec.source)}

        second =
          ask(lacking, fn node ->
            {%{request | spec: packed, children: plan[node]}, @prepare_ms}
          end)

        bytes = Map.new(lacking, &{&1, Source.packed_size(packed.source)})
        outcome(nodes, Map.merge(first, second), bytes)
    end
  end

  # One request to each of `nodes` at once; each answer, or why there was
  # none, by node.
  defp ask(nodes, request) do
    t0 = System.monotonic_time(:millisecond)

    nodes
    |> Enum.map(fn node ->
      {body, ms} = request.(node)
      {node, :erpc.send_request(node, Host, :start, [body]), ms}
    end)
    |> Map.new(fn {node, id, ms} ->
      left = max(ms - (System.monotonic_time(:millisecond) - t0), 0)
      {node, receive_answer(node, id, left, ms)}
    end)
  end

  defp receive_answer(node, id, left, ms) do
    :erpc.receive_response(id, left)
  catch
    :error, {:exception, :undef, _} ->
      {:error,
       {:node_unavailable,
        "node #{node} lacks RingTracer's code (start it with mix ring_tracer.worker)"}}

    :error, {:erpc, _} = reason ->
      {:error, {:node_unavailable, Cluster.call_failure(node, reason, ms)}}

    kind, reason ->
      {:error, {:node_unavailable, "node #{node}: #{inspect({kind, reason})}"}}
  end

  defp outcome(nodes, answers, bytes) do
    started = for {_node, {:ok, list}} <- answers, pair <- list, do: pair

    case Enum.find_value(nodes, &failure(&1, Map.fetch!(answers, &1))) do
      nil ->
        {:ok, Enum.sort(started), Map.new(nodes, &{&1, Map.get(bytes, &1, 0)})}

      {reason, message} ->
        {:error, reason, message, started}
    end
  end

  defp failure(_node, {:ok, _}), do: nil

  defp failure(node, {:build, theirs}) do
    {:error, error} = Build.compare(node, theirs)
    {error.reason, error.message}
  end

  defp failure(node, :need_scene),
    do: {:node_unavailable, "node #{node} asked again for the scene it was just sent"}

  defp failure(_node, {:error, {reason, message}}), do: {reason, message}
end
