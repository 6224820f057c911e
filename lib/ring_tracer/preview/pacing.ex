defmodule RingTracer.Preview.Pacing do
  @moduledoc false
  # How long the live preview's server waits after a piece of its work, so
  # that it spends at most a share of one core while a job runs
  # (`RingTracer.Preview.Server`). The work is measured in the CPU time of
  # the scheduler thread that did it, not in wall time: on a loaded machine
  # the OS takes the core away from the thread in the middle of the work,
  # and wall time would count that as the preview's, making it wait many
  # times longer than its share asks, and the page lag far behind the job.

  # The shortest pause: below it, the work goes on and its debt grows.
  @quantum_ms 20

  @typedoc "Where a piece of work started: wall clock, thread CPU clock, scheduler."
  @opaque mark :: {integer(), integer(), pos_integer()}

  @doc "Marks the start of a piece of work, in the calling process."
  @spec start() :: mark()
  def start,
    do:
      {System.monotonic_time(:microsecond), RingTracer.Native.thread_cpu_us(),
       :erlang.system_info(:scheduler_id)}

  @doc """
  The microseconds of CPU the work since `mark` took: the thread's CPU time
  when the process ran on one scheduler throughout (which then may include
  other processes that ran on it meanwhile, so it errs long), the wall time
  otherwise; never more than the wall time.
  """
  @spec work_us(mark()) :: non_neg_integer()
  def work_us({wall0, cpu0, scheduler}) do
    wall = System.monotonic_time(:microsecond) - wall0
    cpu = RingTracer.Native.thread_cpu_us()

    if cpu0 >= 0 and cpu >= cpu0 and :erlang.system_info(:scheduler_id) == scheduler,
      do: min(cpu - cpu0, wall),
      else: wall
  end

  @doc """
  Whether to pause after `debt_us` of work done since the last pause, for
  the work to be `share` of the time: `{:pause, ms}` once the pause is at
  least #{20} ms, `:go_on` before (the work goes on adding to the debt). A
  pause after each short piece of work would be shorter than a timer's
  practical resolution and, on a loaded machine, take several times as
  long as asked to wake up from: the page would lag far behind its share.

      iex> RingTracer.Preview.Pacing.pause(100, 0.01)
      :go_on
      iex> RingTracer.Preview.Pacing.pause(250, 0.01)
      {:pause, 25}
  """
  @spec pause(non_neg_integer(), number()) :: {:pause, pos_integer()} | :go_on
  def pause(debt_us, share) do
    case wait_ms(debt_us, share) do
      ms when ms >= @quantum_ms -> {:pause, ms}
      _ -> :go_on
    end
  end

  @doc """
  The pause after `work_us` of work for it to be `share` of the time.

      iex> RingTracer.Preview.Pacing.wait_ms(100, 0.01)
      10
      iex> RingTracer.Preview.Pacing.wait_ms(4_000, 0.5)
      4
      iex> RingTracer.Preview.Pacing.wait_ms(0, 0.01)
      0
  """
  @spec wait_ms(non_neg_integer(), number()) :: non_neg_integer()
  def wait_ms(work_us, share) when share > 0 and share <= 1,
    do: round(work_us * (1 - share) / share / 1000)
end
