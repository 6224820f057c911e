defmodule RingTracer.CLI.Console do
  @moduledoc false
  # Where a command writes and which folder it was called from.
  #
  # Booted by the launcher in a VM of its own, a command writes to the VM's
  # stdout and stderr and takes its folder from `RINGTRACER_CWD`. Run by the
  # resident server (`RingTracer.CLI.Server`) for a client, it writes to the
  # client's: the server makes the client's stdout the command's group leader
  # and puts a console naming the client's stderr, folder and umask in the
  # command process (`put/1`). Everything a command writes to stderr goes
  # through `err/0`; the files it creates get `new_file_mode/0`.

  defstruct err: :standard_error, cwd: nil, tty?: nil, umask: nil, home: nil

  @typedoc """
  `err`: the stderr device; `cwd`: the caller's folder (`nil`: from the
  environment); `tty?`: whether stderr is a terminal (`nil`: ask the VM);
  `umask`: the caller's (`nil`: the VM's own applies); `home`: the caller's
  home, what `~` in a path stands for (`nil`: the VM's).
  """
  @type t :: %__MODULE__{
          err: :io.device(),
          cwd: Path.t() | nil,
          tty?: boolean() | nil,
          umask: non_neg_integer() | nil,
          home: Path.t() | nil
        }

  @key {__MODULE__, :console}

  @doc "Makes `console` the calling process's console."
  @spec put(t()) :: :ok
  def put(%__MODULE__{} = console) do
    Process.put(@key, console)
    :ok
  end

  @doc "The calling process's console (the VM's own unless `put/1` was called)."
  @spec get() :: t()
  def get, do: Process.get(@key) || %__MODULE__{}

  @doc """
  The permissions of a file the command creates: `0o666` less the caller's
  umask, or `nil` in a VM of the caller's own, where its umask applies by
  itself.

      iex> RingTracer.CLI.Console.new_file_mode()
      nil
  """
  @spec new_file_mode() :: non_neg_integer() | nil
  def new_file_mode do
    case get().umask do
      nil -> nil
      umask -> Bitwise.band(0o666, Bitwise.bnot(umask))
    end
  end

  @doc """
  The stderr device.

      iex> RingTracer.CLI.Console.err()
      :standard_error
  """
  @spec err() :: :io.device()
  def err, do: get().err

  @doc "The caller's folder."
  @spec cwd() :: Path.t()
  def cwd, do: get().cwd || System.get_env("RINGTRACER_CWD") || File.cwd!()

  @doc "The caller's home: what `~` in a path stands for."
  @spec home() :: Path.t()
  def home, do: get().home || System.user_home!()

  @doc "Whether stderr is a terminal."
  @spec tty?() :: boolean()
  def tty? do
    case get().tty? do
      nil -> match?({:ok, _}, :io.columns(:standard_error))
      tty? -> tty?
    end
  end
end
