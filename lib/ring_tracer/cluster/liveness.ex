defmodule RingTracer.Cluster.Liveness do
  @moduledoc false
  # A job's watch on the other nodes it uses. A node that is frozen (stopped
  # with SIGSTOP, swapping, hung) keeps its connection open, so monitors do not
  # fire and distribution's own tick would take about a minute to notice.
  # This process, which ends with the job's parent, asks each node for a trivial
  # answer every `interval` and disconnects a node that has not answered
  # within `timeout` (the `:liveness` option, default 10 s): the monitors on
  # its processes then fire with `:noconnection`, and the job traces that
  # node's atoms elsewhere, as for any lost node.

  require Logger

  @default_timeout 10_000

  @doc "The default liveness timeout, in milliseconds."
  @spec default_timeout() :: pos_integer()
  def default_timeout, do: @default_timeout

  @doc """
  Starts the watch on `nodes` (this node is left out) for as long as the
  calling process lives. Returns `nil` when there is nothing to watch.
  """
  @spec start([node()], pos_integer()) :: pid() | nil
  def start(nodes, timeout) do
    owner = self()

    case Enum.uniq(nodes) -- [node()] do
      [] ->
        nil

      others ->
        spawn(fn ->
          ref = Process.monitor(owner)
          loop(others, timeout, max(div(timeout, 4), 50), ref)
        end)
    end
  end

  defp loop(nodes, timeout, interval, owner) do
    receive do
      {:DOWN, ^owner, _, _, _} -> exit(:normal)
    after
      interval -> :ok
    end

    requests =
      for n <- nodes, n in Node.list(), do: {n, :erpc.send_request(n, :erlang, :node, [])}

    deadline = System.monotonic_time(:millisecond) + timeout

    alive =
      Enum.filter(requests, fn {n, request} ->
        left = max(deadline - System.monotonic_time(:millisecond), 0)

        try do
          _ = :erpc.receive_response(request, left)
          true
        catch
          :error, {:erpc, :timeout} ->
            Logger.warning(
              "RingTracer: node #{n} has not answered for #{timeout} ms; " <>
                "disconnecting it, its atoms will be traced elsewhere"
            )

            :erlang.disconnect_node(n)
            false

          _, _ ->
            false
        end
      end)

    case alive do
      [] -> :ok
      _ -> loop(Enum.map(alive, &elem(&1, 0)), timeout, interval, owner)
    end
  end
end
