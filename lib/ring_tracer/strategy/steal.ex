defmodule RingTracer.Strategy.Steal do
  @moduledoc """
  Random work stealing, as a modern reference point: an idle child asks a
  random sibling it has not asked since its last success for half of that
  sibling's queued atoms. The sibling replies with a hand-over, empty if it
  has nothing to spare. A child that every sibling has refused is finished.
  The order of victims is random but seeded by the child's index, so a job is
  repeatable.
  """
  @behaviour RingTracer.Strategy

  alias RingTracer.Job.Child
  alias RingTracer.Layout

  @impl true
  def initial_atoms(layout, index), do: Layout.strip(layout, index)

  @impl true
  def idle(child) do
    plan = Map.get(child.strategy_state, :victims) || victims(child)

    case next_victim(plan, child) do
      nil ->
        %{child | status: :finished, strategy_state: %{victims: plan}}

      {victim, plan} ->
        child
        |> Child.send_counted(
          Child.sibling(child, victim),
          :offer,
          {:steal, self(), child.index}
        )
        |> Child.event(:steal, victim)
        |> Child.bump(:offers_sent)
        |> Map.merge(%{status: :stealing, strategy_state: %{victims: plan}})
    end
  end

  @impl true
  def handle_message({:steal, thief, thief_index}, child) do
    g = div(length(child.queue), 2)
    {atoms, child} = Child.take_last(child, g)

    child =
      if g > 0, do: Child.bump(child, :offers_consumed), else: Child.bump(child, :offers_passed)

    {:ok,
     child
     |> Child.hand_over(thief, thief_index, atoms)
     |> Child.event(if(g > 0, do: :give, else: :refuse), thief_index)}
  end

  def handle_message({:handover, _from, []}, child), do: {:ok, idle(child)}

  # Atoms the parent hands out again after a failure: the child's sweep of
  # victims goes on where it was (restarting it would ask every sibling
  # again, most of them idle by then).
  def handle_message({:handover, :parent, atoms}, child),
    do: {:ok, Child.receive_atoms(child, atoms)}

  def handle_message({:handover, _from, atoms}, child),
    do: {:ok, Child.receive_atoms(%{child | strategy_state: %{}}, atoms)}

  def handle_message(_msg, _child), do: :unhandled

  # The order of victims, in constant space whatever the ring's size: the
  # k-th victim is `index + k * step (mod N)` for k = 1..N-1, a permutation
  # of the siblings because `step` is coprime with N. `step` is drawn with a
  # seed of the child's index, so a job is repeatable.
  defp victims(%{index: index, ring_size: n}) do
    step =
      if n > 2 do
        :rand.seed(:exsss, {index + 1, 7, 13})
        coprime(:rand.uniform(n - 1), n)
      else
        1
      end

    %{k: 1, step: step, n: n}
  end

  defp coprime(s, n), do: if(Integer.gcd(s, n) == 1, do: s, else: coprime(rem(s, n - 1) + 1, n))

  # The next victim not known dead, or nil when every sibling has been asked.
  defp next_victim(%{k: k, n: n}, _child) when k >= n, do: nil

  defp next_victim(%{k: k, step: step, n: n} = plan, child) do
    victim = rem(child.index + k * step, n)
    plan = %{plan | k: k + 1}
    if victim in child.dead, do: next_victim(plan, child), else: {victim, plan}
  end
end
