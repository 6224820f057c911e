defmodule RingTracer.Farm.Policy do
  @moduledoc false
  # How a farm's head shares its workers between jobs: a pure callback that
  # takes a view of the farm (the jobs that want workers, the workers and
  # what each works on) and returns what should change. The head carries the
  # effects out, releases first; it asks again whenever a job or a worker
  # comes or goes. The default is `RingTracer.Farm.Policy.Fair`; another is
  # given to `RingTracer.Farm.start_head/1` as `policy: Module`.
  #
  # Effects:
  #
  #   * `{:start, job, nodes}` — a queued job starts its ring on these workers
  #   * `{:grow, job, node}` — a running job's ring gains the worker
  #   * `{:release, job, node}` — a running job lets the worker go (its
  #     children there stop and their work is handed on, as when a node is
  #     lost)

  defmodule View do
    @moduledoc false
    # What a policy sees. `jobs` are those queued or running, in submission
    # order; `workers` every worker that has joined, with the job it works on
    # (`nil`: idle).
    @enforce_keys [:jobs, :workers]
    defstruct [:jobs, :workers]

    @type job :: %{
            id: pos_integer(),
            user: String.t(),
            priority: integer(),
            tags: [String.t()],
            max_workers: pos_integer() | nil,
            state: :queued | :running,
            workers: [node()]
          }
    @type worker :: %{node: node(), tags: [String.t()], job: pos_integer() | nil}
    @type t :: %__MODULE__{jobs: [job()], workers: [worker()]}
  end

  @type effect ::
          {:start, pos_integer(), [node()]}
          | {:grow, pos_integer(), node()}
          | {:release, pos_integer(), node()}

  @doc "What should change, given the farm as it is."
  @callback assign(View.t()) :: [effect()]
end
