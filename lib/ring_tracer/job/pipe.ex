defmodule RingTracer.Job.Pipe do
  @moduledoc """
  Who gets the atom queued in a grandchild's pipe: the grandchild, which is
  about to trace it, or its child, which wants to hand it to a sibling.

  A child keeps two atoms in its grandchild's mailbox: the one being traced
  and the next one, so that the grandchild never waits. The next one is not
  yet started, and at the end of a job (or on a slow machine) it is the atom
  a faster sibling could finish first. Taking it back by message would wait
  for the grandchild to finish its current atom; instead both sides race for
  it in this node's ETS table, once, atomically (`:ets.insert_new/2` on the
  key `{grandchild, atom}`):

    * the grandchild `claim/2`s an atom before tracing it;
    * the child `revoke/2`s it before handing it over;
    * whoever inserts first wins; the loser sees `false`.

  The child `release/2`s the entry when the atom's pixels come back; the
  grandchild deletes a revoked entry when it skips the atom; a child whose
  grandchild died `forget/1`s everything of that grandchild.

  The table belongs to this process, started by the application on every
  node (a grandchild and its child always share a node). A child killed
  outright cannot forget its grandchild's entries, so this process sweeps
  out the entries of dead grandchildren once a minute.
  """
  use GenServer

  @table RingTracer.Names.pipe_table()
  @sweep_ms 60_000

  @doc false
  @spec start_link(term()) :: GenServer.on_start()
  def start_link(_), do: GenServer.start_link(__MODULE__, [], name: __MODULE__)

  @doc "The grandchild takes `atom` for tracing; `false` if its child took it back first."
  @spec claim(pid(), non_neg_integer()) :: boolean()
  def claim(gc, atom) do
    if :ets.insert_new(@table, {{gc, atom}}) do
      true
    else
      :ets.delete(@table, {gc, atom})
      false
    end
  end

  @doc "Whether `gc` has claimed `atom` (started it, for a grandchild that is gone)."
  @spec claimed?(pid(), non_neg_integer()) :: boolean()
  def claimed?(gc, atom), do: :ets.member(@table, {gc, atom})

  @doc "The child takes `atom` back from `gc`'s pipe; `false` if `gc` has started it."
  @spec revoke(pid(), non_neg_integer()) :: boolean()
  def revoke(gc, atom), do: :ets.insert_new(@table, {{gc, atom}})

  @doc "The child has `atom`'s pixels: the claim is over."
  @spec release(pid(), non_neg_integer()) :: true
  def release(gc, atom), do: :ets.delete(@table, {gc, atom})

  @doc "Forgets every claim and revocation of `gc` (dead or stopped)."
  @spec forget(pid()) :: true
  def forget(gc), do: :ets.match_delete(@table, {{gc, :_}})

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
        fn {{gc, _} = key}, acc -> if Process.alive?(gc), do: acc, else: [key | acc] end,
        [],
        @table
      )

    Enum.each(dead, &:ets.delete(@table, &1))
  end

  defp schedule_sweep, do: Process.send_after(self(), :sweep, @sweep_ms)
end
