defmodule RingTracer.Test.OSNode do
  @moduledoc """
  A RingTracer command run as a real OS process, booted straight from `erl`
  with this node's compiled code (`RingTracer.CLI`), its output collected
  through a port.
  """

  defstruct [:port, :os_pid, :output]

  @type t :: %__MODULE__{port: port(), os_pid: non_neg_integer(), output: String.t()}

  @doc """
  Starts `ringtracer ARGS...` as an OS process. Options: `:vm_args`, `:env`,
  and `:prefix`, a command that runs `erl` (for instance
  `["ip", "netns", "exec", NS]`).
  """
  @spec start([String.t()], keyword()) :: t()
  def start(args, opts \\ []) do
    erl = System.find_executable("erl")
    paths = Enum.flat_map(code_paths(), &["-pa", &1])

    argv =
      ["-noshell"] ++
        Keyword.get(opts, :vm_args, []) ++
        paths ++
        ["-s", "Elixir.RingTracer.CLI", "main", "-extra" | args]

    {exe, argv} =
      case Keyword.get(opts, :prefix, []) do
        [] -> {erl, argv}
        [command | rest] -> {System.find_executable(command), rest ++ [erl | argv]}
      end

    port =
      Port.open({:spawn_executable, exe}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: argv,
        env: Keyword.get(opts, :env, [])
      ])

    {:os_pid, os_pid} = Port.info(port, :os_pid)
    %__MODULE__{port: port, os_pid: os_pid, output: ""}
  end

  @doc "Waits until the output contains `text`; returns the node and all output so far."
  @spec await(t(), String.t(), timeout()) ::
          {:ok, t()} | {:exit, integer(), t()} | {:timeout, t()}
  def await(%__MODULE__{port: port} = node, text, timeout \\ 30_000) do
    if String.contains?(node.output, text) do
      {:ok, node}
    else
      receive do
        {^port, {:data, data}} -> await(%{node | output: node.output <> data}, text, timeout)
        {^port, {:exit_status, status}} -> {:exit, status, drain(node)}
      after
        timeout -> {:timeout, node}
      end
    end
  end

  @doc "Waits for the process to exit; returns its status and output."
  @spec wait_exit(t(), timeout()) :: {integer() | :timeout, String.t()}
  def wait_exit(%__MODULE__{port: port} = node, timeout \\ 30_000) do
    receive do
      {^port, {:data, data}} -> wait_exit(%{node | output: node.output <> data}, timeout)
      {^port, {:exit_status, status}} -> {status, drain(node).output}
    after
      timeout -> {:timeout, node.output}
    end
  end

  @doc "Kills the OS process."
  @spec stop(t()) :: :ok
  def stop(%__MODULE__{os_pid: pid, port: port}) do
    System.cmd("kill", ["-KILL", Integer.to_string(pid)], stderr_to_stdout: true)

    try do
      Port.close(port)
    rescue
      ArgumentError -> :ok
    end

    :ok
  end

  defp drain(%__MODULE__{port: port} = node) do
    receive do
      {^port, {:data, data}} -> drain(%{node | output: node.output <> data})
    after
      0 -> node
    end
  end

  @doc "The application's, Elixir's and Logger's code: what the launcher puts in the code path."
  @spec code_paths() :: [String.t()]
  def code_paths do
    [:ring_tracer, :elixir, :logger]
    |> Enum.map(&(:code.lib_dir(&1, :ebin) |> List.to_string()))
  end
end
