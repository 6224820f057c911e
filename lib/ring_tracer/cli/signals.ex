defmodule RingTracer.CLI.Signals do
  @moduledoc false
  # Interrupting a command booted by the launcher.
  #
  # The BEAM cannot catch SIGINT (Ctrl-C opens its break menu), so the
  # launcher boots it with the break handler off (`+Bi`), stays its parent,
  # and turns a SIGINT it receives into SIGUSR2 for the VM; SIGTERM it
  # passes on as is. In the VM this handler, added to OTP's
  # `erl_signal_server`, tells the command's process
  # `{RingTracer.CLI.Signals, :sigint | :sigterm}`, and the command cancels
  # its job and exits with 130 or 143. A second Ctrl-C makes the launcher
  # kill the VM outright.
  @behaviour :gen_event

  @doc """
  Cancels the command's job (`RingTracer.cancel/1`: on a signal, or when
  the command cannot go on) and drops what the job sent that is still in
  the mailbox.
  """
  @spec cancel(%{id: reference(), pid: pid()}) :: :ok
  def cancel(%{id: id} = handle) do
    :ok = RingTracer.cancel(handle)
    flush(id)
  end

  defp flush(id) do
    receive do
      {RingTracer, ^id, _} -> flush(id)
    after
      0 -> :ok
    end
  end

  @doc """
  From now on, SIGUSR2 (the launcher's SIGINT) and SIGTERM go to `pid` as
  messages (the CLI calls it once, first thing).

  The launcher forwards an interrupt only once the VM catches SIGUSR2 (it
  reads the VM's caught signals in `/proc`): until then it keeps it, so
  that a Ctrl-C or SIGTERM during the VM's boot is not lost, nor kills the
  VM, but reaches the command as soon as this handler is in place.
  """
  @spec forward_to(pid()) :: :ok
  def forward_to(pid) do
    # OTP's own handler would stop the VM on SIGTERM: ours replaces it.
    :ok =
      :gen_event.swap_handler(
        :erl_signal_server,
        {:erl_signal_handler, :swap},
        {__MODULE__, pid}
      )

    # SIGUSR2 last: the launcher takes it as the sign that this is in place.
    :os.set_signal(:sigterm, :handle)
    :os.set_signal(:sigusr2, :handle)
    :ok
  end

  @doc """
  The interrupt already waiting in this process's mailbox, if any: for a
  command to check between steps that no signal can cut short (a scene's
  parse), so that it stops before the next one.
  """
  @spec pending() :: :sigint | :sigterm | nil
  def pending do
    receive do
      {__MODULE__, signal} -> signal
    after
      0 -> nil
    end
  end

  @doc "The exit status for an interrupt: 128 plus the signal's number."
  @spec exit_status(:sigint | :sigterm) :: 130 | 143
  def exit_status(:sigint), do: 130
  def exit_status(:sigterm), do: 143

  @impl :gen_event
  def init({pid, _old}) when is_pid(pid), do: {:ok, pid}

  @impl :gen_event
  def handle_event(:sigusr2, pid), do: tell(pid, :sigint)
  def handle_event(:sigterm, pid), do: tell(pid, :sigterm)
  def handle_event(_other, pid), do: {:ok, pid}

  @impl :gen_event
  def handle_call(_request, pid), do: {:ok, :ok, pid}

  @impl :gen_event
  def handle_info(_msg, pid), do: {:ok, pid}

  defp tell(pid, signal) do
    send(pid, {__MODULE__, signal})
    {:ok, pid}
  end
end
