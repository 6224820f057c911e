defmodule RingTracer.Job.Pipe do
  @moduledoc false
  # Who gets the atom queued in a grandchild's pipe: the grandchild, which is
  # about to trace it, or its child, which wants to hand it to a sibling.
  #
  # A child keeps two atoms in its grandchild's mailbox: the one being traced
  # and the next one, so that the grandchild never waits. The next one is not
  # yet started, and at the end of a job (or on a slow machine) it is the atom
  # a faster sibling could finish first. Taking it back by message would wait
  # for the grandchild to finish its current atom; instead both sides race for
  # it in this node's ETS table, once, atomically (`:ets.insert_new/2` on the
  # key `{grandchild, atom}`):
  #
  #   * the grandchild `claim/2`s an atom before tracing it;
  #   * the child `revoke/2`s it before handing it over;
  #   * whoever inserts first wins; the loser sees `false`.
  #
  # The child `release/2`s the entry when the atom's pixels come back; the
  # grandchild deletes a revoked entry when it skips the atom; a child whose
  # grandchild died `forget/1`s everything of that grandchild.
  #
  # ## Cutting the atom being traced
  #
  # A grandchild may trace a long atom in parts (`RingTracer.Job.Grandchild`):
  # the entry then counts the parts it has started. Before each part after
  # the first it takes the next one (`next/2`); its child may `cut/3` the atom
  # meanwhile, which takes every part not yet started, for a faster sibling.
  # Both are one `:ets.update_counter/3` on the same entry, so each part goes
  # to exactly one side: the cut adds a million to the count, and returns
  # how many parts the grandchild had started; the grandchild's next
  # `next/2` sees the mark, and it stops there.
  #
  # The table belongs to this process, started by the application on every
  # node (a grandchild and its child always share a node). A child killed
  # outright cannot forget its grandchild's entries, so this process sweeps
  # out the entries of dead grandchildren once a minute.
  use GenServer

  alias RingTracer.Layout

  @table RingTracer.Names.pipe_table()
  @sweep_ms 60_000

  @doc false
  @spec start_link(term()) :: GenServer.on_start()
  def start_link(_), do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  # Added to an entry's count of started parts by a cut (and by a grandchild
  # that failed on an atom, so that no cut follows): far above any count.
  @cut 1_000_000

  @doc "The grandchild takes `atom` for tracing; `false` if its child took it back first."
  @spec claim(pid(), Layout.atom_id()) :: boolean()
  def claim(gc, atom), do: won(:ets.insert_new(@table, {{gc, atom}, 1}), gc, atom)

  @doc "Whether `gc` has claimed `atom` (started it, for a grandchild that is gone)."
  @spec claimed?(pid(), Layout.atom_id()) :: boolean()
  def claimed?(gc, atom), do: :ets.member(@table, {gc, atom})

  @doc "How many parts of `atom` `gc` has started (0: none, or taken back)."
  @spec started(pid(), Layout.atom_id()) :: non_neg_integer()
  def started(gc, atom) do
    case :ets.lookup(@table, {gc, atom}) do
      [{_, n}] when n < @cut -> n
      [_] -> @cut
      [] -> 0
    end
  end

  @doc "The child takes `atom` back from `gc`'s pipe; `false` if `gc` has started it."
  @spec revoke(pid(), Layout.atom_id()) :: boolean()
  def revoke(gc, atom), do: :ets.insert_new(@table, {{gc, atom}, 0})

  @doc """
  The grandchild, tracing `atom` in parts, takes the next part: `true`, or
  `false` if its child has cut the atom (the grandchild then stops, and
  deletes the entry: the child is done with it).
  """
  @spec next(pid(), Layout.atom_id()) :: boolean()
  def next(gc, atom), do: won(:ets.update_counter(@table, {gc, atom}, {2, 1}) < @cut, gc, atom)

  # The grandchild's side: on losing, it deletes the entry (its child is
  # done with it).
  defp won(true, _gc, _atom), do: true

  defp won(false, gc, atom) do
    :ets.delete(@table, {gc, atom})
    false
  end

  @doc """
  The child cuts `atom`, which `gc` is tracing in `n` parts: `{:ok, started}`,
  where the parts from `started` on are the child's now, or `:none` when
  there is nothing to take (every part started, the atom finished or failed,
  or not started at all: then it is not the atom being traced).
  """
  @spec cut(pid(), Layout.atom_id(), pos_integer()) :: {:ok, pos_integer()} | :none
  def cut(gc, atom, n) do
    case add(gc, atom, @cut) do
      v when is_integer(v) and v - @cut >= 1 and v - @cut < n -> {:ok, v - @cut}
      _ -> :none
    end
  end

  # Adds `k` to the entry's count and returns it; `nil` without an entry
  # (none is made: one would look like a revocation to the grandchild).
  defp add(gc, atom, k) do
    :ets.update_counter(@table, {gc, atom}, {2, k})
  rescue
    ArgumentError -> nil
  end

  @doc """
  The grandchild failed on `atom`: no cut may take its parts from now on.
  Returns how many parts an earlier cut left it (`nil`: no cut came).
  """
  @spec fail(pid(), Layout.atom_id()) :: pos_integer() | nil
  def fail(gc, atom) do
    case add(gc, atom, @cut) do
      v when is_integer(v) and v >= 2 * @cut ->
        # The child, which cut, is done with the entry (it retries the piece).
        :ets.delete(@table, {gc, atom})
        v - 2 * @cut

      _ ->
        nil
    end
  end

  @doc "The child has `atom`'s pixels: the claim is over."
  @spec release(pid(), Layout.atom_id()) :: true
  def release(gc, atom), do: :ets.delete(@table, {gc, atom})

  @doc "Forgets every claim and revocation of `gc` (dead or stopped)."
  @spec forget(pid()) :: true
  def forget(gc), do: :ets.match_delete(@table, {{gc, :_}, :_})

  @impl GenServer
  def init([]) do
    :ets.new(@table, [
      :named_table,
      :public,
      :set,
      read_concurrency: false,
      write_concurrency: true
    ])

    schedule_sweep()
    {:ok, nil}
  end

  @impl GenServer
  def handle_info(:sweep, state) do
    sweep()
    schedule_sweep()
    {:noreply, state}
  end

  @doc false
  @spec sweep() :: :ok
  def sweep do
    dead =
      :ets.foldl(
        fn {{gc, _} = key, _}, acc -> if Process.alive?(gc), do: acc, else: [key | acc] end,
        [],
        @table
      )

    Enum.each(dead, &:ets.delete(@table, &1))
  end

  defp schedule_sweep, do: Process.send_after(self(), :sweep, @sweep_ms)
end
