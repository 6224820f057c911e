defmodule RingTracer.Farm.Store do
  @moduledoc false
  # The head's durable state, in Mnesia (disc copies in the head's folder):
  # the jobs (`RingTracer.Farm.Job`), the frames done (one row per
  # `{job, frame}`) and the last id given. A frame's row is written after
  # its file, so a row means a whole file; every change is a transaction,
  # logged before it returns, so `kill -9` of the head loses none.

  alias RingTracer.Error
  alias RingTracer.Farm.Job

  @jobs :ring_tracer_farm_job
  @frames :ring_tracer_farm_frame
  @ids :ring_tracer_farm_id
  @tables [@jobs, @frames, @ids]
  @wait_ms 30_000

  @doc """
  Starts Mnesia with its files in `dir` (made if missing) and the farm's
  tables, on this node alone. The schema belongs to this node's name: a
  head restarted under another name does not see its jobs.
  """
  @spec open(Path.t()) :: :ok | {:error, Error.t()}
  def open(dir) do
    _ = :mnesia.stop()
    :ok = Application.load(:mnesia) |> loaded()
    Application.put_env(:mnesia, :dir, String.to_charlist(dir))

    with :ok <- schema(dir),
         :ok <- mnesia(:mnesia.start(), dir),
         :ok <- Enum.reduce_while(@tables, :ok, &create_table/2),
         :ok <- wait(dir) do
      :ok
    end
  end

  defp loaded(:ok), do: :ok
  defp loaded({:error, {:already_loaded, :mnesia}}), do: :ok

  defp schema(dir) do
    case :mnesia.create_schema([node()]) do
      :ok -> :ok
      {:error, {_, {:already_exists, _}}} -> :ok
      {:error, reason} -> mnesia({:error, reason}, dir)
    end
  end

  defp create_table(table, :ok) do
    attributes =
      case table do
        @jobs -> [:id, :job]
        @frames -> [:key, :done_at]
        @ids -> [:key, :last]
      end

    case :mnesia.create_table(table, attributes: attributes, disc_copies: [node()]) do
      {:atomic, :ok} -> {:cont, :ok}
      {:aborted, {:already_exists, ^table}} -> {:cont, :ok}
      {:aborted, reason} -> {:halt, {:error, Error.new(:farm, "Mnesia: #{inspect(reason)}")}}
    end
  end

  defp wait(dir) do
    case :mnesia.wait_for_tables(@tables, @wait_ms) do
      :ok -> :ok
      other -> mnesia({:error, other}, dir)
    end
  end

  defp mnesia(:ok, _dir), do: :ok

  defp mnesia({:error, reason}, dir),
    do: {:error, Error.new(:farm, "#{dir}: Mnesia could not start: #{inspect(reason)}")}

  @doc "Stops Mnesia (tests, and a head that stops)."
  @spec close() :: :ok
  def close do
    _ = :mnesia.stop()
    :ok
  end

  @doc "Stores a new job under the next id, and returns it with that id."
  @spec insert(Job.t()) :: Job.t()
  def insert(%Job{} = job) do
    durable(fn ->
      last =
        case :mnesia.read(@ids, :job, :write) do
          [{@ids, :job, last}] -> last
          [] -> 0
        end

      job = %{job | id: last + 1}
      :ok = :mnesia.write({@ids, :job, last + 1})
      :ok = :mnesia.write({@jobs, job.id, job})
      job
    end)
  end

  @doc "Replaces a job's row."
  @spec put(Job.t()) :: :ok
  def put(%Job{id: id} = job), do: durable(fn -> :mnesia.write({@jobs, id, job}) end)

  @doc "A job by id."
  @spec get(pos_integer()) :: {:ok, Job.t()} | :error
  def get(id) do
    case transaction(fn -> :mnesia.read(@jobs, id) end) do
      [{@jobs, ^id, job}] -> {:ok, job}
      [] -> :error
    end
  end

  @doc "Every job, by id."
  @spec all() :: [Job.t()]
  def all do
    transaction(fn ->
      :mnesia.foldl(fn {@jobs, _id, job}, acc -> [job | acc] end, [], @jobs)
    end)
    |> Enum.sort_by(& &1.id)
  end

  @doc """
  Records frame `n` of job `id` as done (its file is on disk). A frame
  recorded already keeps its row and is counted as stored twice
  (`twice/0`): the farm never traces a frame done, so that count is 0.
  """
  @spec frame_done(pos_integer(), pos_integer()) :: :ok
  def frame_done(id, n) do
    at = System.os_time(:millisecond)

    durable(fn ->
      case :mnesia.read(@frames, {id, n}, :write) do
        [] -> :mnesia.write({@frames, {id, n}, at})
        [_] -> :mnesia.write({@ids, :twice, twice_in_transaction() + 1})
      end
    end)
  end

  @doc "How many frames were stored again after they were done (see `frame_done/2`)."
  @spec twice() :: non_neg_integer()
  def twice, do: transaction(&twice_in_transaction/0)

  defp twice_in_transaction do
    case :mnesia.read(@ids, :twice) do
      [{@ids, :twice, count}] -> count
      [] -> 0
    end
  end

  @doc "The frames of job `id` done, in order."
  @spec done(pos_integer()) :: [pos_integer()]
  def done(id) do
    transaction(fn ->
      :mnesia.match_object({@frames, {id, :_}, :_})
    end)
    |> Enum.map(fn {@frames, {_, n}, _} -> n end)
    |> Enum.sort()
  end

  @doc "Whether frame `n` of job `id` is done."
  @spec done?(pos_integer(), pos_integer()) :: boolean()
  def done?(id, n), do: transaction(fn -> :mnesia.read(@frames, {id, n}) end) != []

  defp transaction(fun) do
    case :mnesia.transaction(fun) do
      {:atomic, value} -> value
      {:aborted, reason} -> exit({:mnesia, reason})
    end
  end

  # A change that must survive `kill -9` of the head, and a crash of its
  # machine: the transaction log synced to disk before the caller goes on.
  defp durable(fun) do
    value = transaction(fun)
    :ok = :mnesia.sync_log()
    value
  end
end
