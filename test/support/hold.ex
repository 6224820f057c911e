defmodule RingTracer.Test.Hold do
  @moduledoc """
  Holds a node's render children still: a process on that node suspends
  them, and a suspension lasts while the process that made it lives.
  """

  @doc """
  Suspends every child under `RingTracer.Children` on `node` and returns
  once they are suspended; they stay so until that node stops.
  """
  @spec children(node()) :: :ok
  def children(node) do
    ref = make_ref()
    Node.spawn(node, __MODULE__, :suspend_and_wait, [self(), ref])

    receive do
      {^ref, :held} -> :ok
    after
      10_000 -> raise "children on #{node} were not suspended within 10 s"
    end
  end

  @doc false
  @spec suspend_and_wait(pid(), reference()) :: no_return()
  def suspend_and_wait(caller, ref) do
    for {_, pid, _, _} <- DynamicSupervisor.which_children(RingTracer.Children), is_pid(pid) do
      :erlang.suspend_process(pid)
    end

    send(caller, {ref, :held})
    Process.sleep(:infinity)
  end
end
