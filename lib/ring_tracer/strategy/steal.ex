defmodule RingTracer.Strategy.Steal do
  @moduledoc false
  # Random work stealing, as a modern reference point: an idle child asks a
  # random sibling it has not asked since its last success for half of that
  # sibling's queued atoms. The sibling replies with a hand-over, empty if it
  # has nothing to spare. A child that every sibling has refused is finished.
  # The order of victims is random but seeded by the child's index, so a job is
  # repeatable.

  use RingTracer.Strategy

  @impl true
  def options(options, _layout), do: RingTracer.Strategy.no_options(options, :steal)

  @impl true
  def idle(view, state) do
    plan = Map.get(state, :victims) || victims(view)

    case next_victim(plan, view) do
      nil ->
        {%{victims: plan}, [:finished]}

      {victim, plan} ->
        {%{victims: plan},
         [
           {:send, {:sibling, victim}, :offer, {:steal, view.pid, view.index}},
           {:event, :steal, victim},
           {:stat, :offers_sent}
         ]}
    end
  end

  @impl true
  def handle_message({:steal, thief, thief_index}, view, state) do
    g = div(view.queued, 2)
    {stat, event} = if g > 0, do: {:offers_consumed, :give}, else: {:offers_passed, :refuse}
    {state, [{:stat, stat}, {:give, thief, thief_index, g}, {:event, event, thief_index}]}
  end

  def handle_message({:handover, _from, []}, view, state), do: idle(view, state)

  # Atoms the parent hands out again after a failure: the child's sweep of
  # victims goes on where it was (restarting it would ask every sibling
  # again, most of them idle by then).
  # Atoms from the parent (a new frame, or atoms of a dead sibling) are new
  # work: siblings that refused before may have some to spare again.
  def handle_message({:handover, :parent, atoms}, _view, _state), do: {%{}, [{:queue, atoms}]}
  def handle_message({:handover, _from, atoms}, _view, _state), do: {%{}, [{:queue, atoms}]}

  # The sibling we asked may be gone; the others still trace what they hold.
  def handle_message({:siblings_died, _dead}, %{status: :idle}, state),
    do: {state, [:finished]}

  def handle_message(_message, _view, state), do: {state, []}

  # The order of victims, in constant space whatever the ring's size: the
  # k-th victim is `index + k * step (mod N)` for k = 1..N-1, a permutation
  # of the siblings because `step` is coprime with N. `step` is drawn with a
  # seed of the child's index, so a job is repeatable.
  defp victims(%{index: index, ring_size: n}) do
    step =
      if n > 2 do
        {draw, _} = :rand.uniform_s(n - 1, :rand.seed_s(:exsss, {index + 1, 7, 13}))
        coprime(draw, n)
      else
        1
      end

    %{k: 1, step: step, n: n}
  end

  defp coprime(s, n), do: if(Integer.gcd(s, n) == 1, do: s, else: coprime(rem(s, n - 1) + 1, n))

  # The next victim not known dead, or nil when every sibling has been asked.
  defp next_victim(%{k: k, n: n}, _view) when k >= n, do: nil

  defp next_victim(%{k: k, step: step, n: n} = plan, view) do
    victim = rem(view.index + k * step, n)
    plan = %{plan | k: k + 1}
    if victim in view.dead, do: next_victim(plan, view), else: {victim, plan}
  end
end
