defmodule RingTracer.Test.DelayedStrategy do
  @moduledoc """
  A test-only wrapper around a strategy that delays the messages it has its
  processes send, as a slow or busy network would, and so reorders them.

  Options: `:inner` — the wrapped strategy, `{module, options}`;
  `:handover_delay` — milliseconds every hand-over a child makes takes;
  `:jitter` — at most this many milliseconds more, drawn at random, on every
  message a child's strategy sends and every hand-over (default 0).

  A delayed message goes through a short-lived relay process that sleeps,
  then forwards it: the child sends and counts exactly the message it would
  have sent.
  """
  use RingTracer.Strategy

  @doc """
  Wraps the strategy of `render/2`'s options `opts` (`:strategy`, default
  `:ring`) with `delays`; the ring's `:part_us`, `:part_rows` and
  `:cut_faster` among them go to the inner strategy.
  """
  @spec wrap(keyword(), keyword()) :: RingTracer.Strategy.t()
  def wrap(opts, delays) do
    {own, delays} = Keyword.split(delays, [:part_us, :part_rows, :cut_faster])

    inner =
      case Keyword.get(opts, :strategy, :ring) do
        {name, options} -> {name, options ++ own}
        name -> {name, own}
      end

    {__MODULE__, [inner: inner] ++ delays}
  end

  # The inner strategy checks and completes its own options.
  @impl true
  def options(options, layout) do
    case RingTracer.Strategies.resolve(options[:inner], layout) do
      {:ok, inner} -> {:ok, Keyword.put(options, :inner, inner)}
      {:error, error} -> {:error, error.message}
    end
  end

  @impl true
  def initial_atoms(layout, index, options) do
    {module, inner} = options[:inner]
    module.initial_atoms(layout, index, inner)
  end

  @impl true
  def init(options) do
    {module, inner} = options[:inner]
    module.init(inner)
  end

  @impl true
  def parts(view, state), do: inner(view).parts(inner_view(view), state)

  @impl true
  def idle(view, state), do: child(view, &inner(view).idle(&1, state))

  @impl true
  def handle_message(message, view, state),
    do: child(view, &inner(view).handle_message(message, &1, state))

  @impl true
  def handover_news(view, state), do: inner(view).handover_news(inner_view(view), state)

  @impl true
  def parent_start(view, options) do
    {module, inner} = options[:inner]
    module.parent_start(inner_view(view), inner)
  end

  @impl true
  def parent_atom_done(view, state, index),
    do: inner(view).parent_atom_done(inner_view(view), state, index)

  @impl true
  def parent_frame(view, state, frame),
    do: inner(view).parent_frame(inner_view(view), state, frame)

  @impl true
  def parent_joined(view, state, joined),
    do: inner(view).parent_joined(inner_view(view), state, joined)

  @impl true
  def parent_info(message, view, state),
    do: inner(view).parent_info(message, inner_view(view), state)

  defp inner(view), do: elem(view.options[:inner], 0)
  defp inner_view(view), do: %{view | options: elem(view.options[:inner], 1)}

  defp child(view, callback) do
    {state, effects} = callback.(inner_view(view))
    {state, Enum.map(effects, &delay(&1, view))}
  end

  defp delay({:send, to, kind, msg}, view) when to != :parent do
    case jitter(view) do
      0 -> {:send, to, kind, msg}
      ms -> {:send, relay(resolve(to, view), ms), kind, msg}
    end
  end

  defp delay({:give, pid, index, n}, view), do: delay({:give, pid, index, n, nil}, view)

  defp delay({:cut, pid, index, keep}, view), do: {:cut, handover_to(pid, view), index, keep}

  defp delay({:give, pid, index, n, part}, view),
    do: {:give, handover_to(pid, view), index, n, part}

  defp delay(effect, _view), do: effect

  # Where a hand-over goes: to the offerer, or through a relay that holds it.
  defp handover_to(pid, view) do
    case Keyword.get(view.options, :handover_delay, 0) + jitter(view) do
      0 -> pid
      ms -> relay(pid, ms)
    end
  end

  defp jitter(view) do
    case Keyword.get(view.options, :jitter, 0) do
      0 -> 0
      max -> :rand.uniform(max + 1) - 1
    end
  end

  defp resolve({:sibling, index}, view), do: RingTracer.Job.Directory.sibling(view.job, index)
  defp resolve(pid, _view) when is_pid(pid), do: pid

  defp relay(to, ms) do
    spawn(fn ->
      receive do
        msg ->
          Process.sleep(ms)
          send(to, msg)
      end
    end)
  end
end
