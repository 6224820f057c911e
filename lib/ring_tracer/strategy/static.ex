defmodule RingTracer.Strategy.Static do
  @moduledoc "Static division: each child traces its own strip and nothing else."
  @behaviour RingTracer.Strategy

  alias RingTracer.Layout

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  @impl true
  def idle(child), do: %{child | status: :finished}

  @impl true
  def handle_message(_msg, _child), do: :unhandled
end
