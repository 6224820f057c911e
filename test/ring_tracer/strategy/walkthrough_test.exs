defmodule RingTracer.Strategy.WalkthroughTest do
  # The strategy of docs/strategies.md's walk-through, as written there.
  use ExUnit.Case, async: false

  alias RingTracer.Strategy.View
  alias RingTracer.TestScenes

  defmodule AskLeft do
    @moduledoc "An idle child asks its left sibling for one atom; refused, it is finished."
    use RingTracer.Strategy

    # Out of atoms: ask the left sibling, and count it as an offer.
    @impl true
    def idle(view, state) do
      {state,
       [
         {:send, view.left, :offer, {:ask, view.pid, view.index}},
         {:event, :offer, view.left_index},
         {:stat, :offers_sent}
       ]}
    end

    # Asked: one atom if any is queued, otherwise an empty hand-over (a refusal).
    @impl true
    def handle_message({:ask, pid, index}, view, state) do
      n = if view.queued > 0, do: 1, else: 0
      {state, [{:give, pid, index, n}, {:event, if(n > 0, do: :give, else: :refuse), index}]}
    end

    # Refused: finished.
    def handle_message({:handover, _from, []}, _view, state), do: {state, [:finished]}

    # Our left sibling died while we waited for its answer: ask the new one.
    def handle_message({:siblings_died, _dead}, %{status: :idle} = view, state),
      do: idle(view, state)

    # Anything else (atoms handed over, among them): the default.
    def handle_message(message, view, state), do: super(message, view, state)
  end

  test "the walk-through's strategy gives the byte-identical image" do
    reference = TestScenes.reference("balls_s1.nff", 40, 30)

    {:ok, result} =
      RingTracer.render(TestScenes.path("balls_s1.nff"),
        strategy: {AskLeft, []},
        children: 4,
        atoms: 8,
        speeds: [1, 1, 4, 1],
        width: 40,
        height: 30
      )

    assert result.pixels == reference
    assert Enum.sort(Enum.map(result.atoms, & &1.atom)) == Enum.to_list(0..31)
    assert result.messages.offer.count == Enum.sum(Enum.map(result.children, & &1.offers_sent))
  end

  test "its rule, without processes" do
    view = %View{
      job: make_ref(),
      index: 1,
      pid: self(),
      ring_size: 4,
      status: :working,
      queued: 3
    }

    assert {_, [{:give, _pid, 2, 1}, {:event, :give, 2}]} =
             AskLeft.handle_message({:ask, self(), 2}, view, %{})

    assert {_, [{:give, _pid, 2, 0}, {:event, :refuse, 2}]} =
             AskLeft.handle_message({:ask, self(), 2}, %{view | queued: 0}, %{})
  end
end
