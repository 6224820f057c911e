defmodule RingTracer.Strategy.Static do
  @moduledoc false
  # Static division: each child traces its own strip and nothing else.

  use RingTracer.Strategy

  @impl true
  def options(options, _layout), do: RingTracer.Strategy.no_options(options, :static)

  @impl true
  def idle(_view, state), do: {state, [:finished]}
end
