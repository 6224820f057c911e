defmodule RingTracer.Strategy do
  @moduledoc """
  A load-balancing strategy: what a child does when it runs out of atoms,
  and what it does with strategy messages from its siblings or parent.

  Every strategy works on the same atoms, with the same kernel, and gives
  byte-identical images; they differ in who traces which atom, when, and
  how many messages that costs.

  | name | module | idea |
  |---|---|---|
  | `:static` | `RingTracer.Strategy.Static` | N strips, no rebalancing (the paper's "divisão simples") |
  | `:master` | `RingTracer.Strategy.Master` | the parent hands out one atom at a time ("divisão complexa") |
  | `:ring` | `RingTracer.Strategy.Ring` | the paper's ring of help offers (default) |
  | `:steal` | `RingTracer.Strategy.Steal` | an idle child steals half of a random sibling's atoms |

  Child callbacks receive and return the child's state (a map, see
  `RingTracer.Job.Child`); they use `RingTracer.Job.Child.send_counted/4` so
  that every message is counted by kind. Parent callbacks are optional.
  """

  alias RingTracer.Layout

  @typedoc "A child's state (see `RingTracer.Job.Child`)."
  @type child :: map()
  @typedoc "The parent's state (see `RingTracer.Job.Parent`)."
  @type parent :: map()

  @doc "The atoms a child holds at the start."
  @callback initial_atoms(Layout.t(), index :: non_neg_integer()) :: [Layout.atom_id()]

  @doc "Called when the child has nothing queued and nothing in its grandchild's pipe."
  @callback idle(child()) :: child()

  @doc "A message the child itself does not know; `:unhandled` if the strategy does not either."
  @callback handle_message(term(), child()) :: {:ok, child()} | :unhandled

  @doc "The parent, once the children are linked."
  @callback parent_start(parent()) :: parent()

  @doc "The parent, each time a new atom arrives from child `index`."
  @callback parent_atom_done(parent(), index :: non_neg_integer()) :: parent()

  @doc """
  The parent, on a message it does not know itself (for instance the reply
  of a task the strategy started in `parent_start/1`).
  """
  @callback parent_info(parent(), msg :: term()) :: parent()

  @optional_callbacks parent_start: 1, parent_atom_done: 2, parent_info: 2

  @strategies %{
    static: RingTracer.Strategy.Static,
    master: RingTracer.Strategy.Master,
    ring: RingTracer.Strategy.Ring,
    steal: RingTracer.Strategy.Steal
  }

  @doc """
  The module of a strategy name.

      iex> RingTracer.Strategy.module(:ring)
      {:ok, RingTracer.Strategy.Ring}
      iex> RingTracer.Strategy.module(:lottery)
      :error
  """
  @spec module(atom()) :: {:ok, module()} | :error
  def module(name), do: Map.fetch(@strategies, name)

  @doc "Every strategy name."
  @spec names() :: [atom()]
  def names, do: [:static, :master, :ring, :steal]
end
