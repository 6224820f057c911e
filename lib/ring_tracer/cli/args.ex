defmodule RingTracer.CLI.Args do
  @moduledoc false
  # Command-line parsing shared by every command: `OptionParser` with strict
  # switches, plus what people expect of a command line: `--help`/`-h`, a
  # suggestion for a mistyped option, and errors that name the bad value and
  # what is accepted.

  @typedoc "What each switch accepts, in words, for error messages."
  @type accepted :: %{optional(atom()) => String.t()}

  @doc """
  Parses `argv` against `switches` (`OptionParser`'s strict types, with
  `aliases`). `:help` when `--help` or `-h` is among them.

      iex> RingTracer.CLI.Args.parse(["--childs", "4"], [children: :integer], %{})
      {:error, "unknown option --childs (did you mean --children?)"}
      iex> RingTracer.CLI.Args.parse(["--children", "abc"], [children: :integer], %{children: "an integer from 1 to 16384"})
      {:error, "--children takes an integer from 1 to 16384, got: abc"}
      iex> RingTracer.CLI.Args.parse(["-h"], [children: :integer], %{})
      :help
      iex> RingTracer.CLI.Args.parse(["a.nff", "--children", "3"], [children: :integer], %{})
      {:ok, [children: 3], ["a.nff"]}
  """
  @spec parse([String.t()], keyword(), accepted(), keyword()) ::
          {:ok, keyword(), [String.t()]} | :help | {:error, String.t()}
  def parse(argv, switches, accepted, aliases \\ []) do
    if Enum.any?(argv, &(&1 in ["--help", "-h"])) do
      :help
    else
      case OptionParser.parse(argv, strict: switches, aliases: aliases) do
        {opts, args, []} -> {:ok, opts, args}
        {_, _, [{name, value} | _]} -> {:error, invalid(name, value, switches, accepted)}
      end
    end
  end

  defp invalid(name, value, switches, accepted) do
    key = name |> String.trim_leading("-") |> String.replace("-", "_")
    known = Enum.find(Keyword.keys(switches), &(Atom.to_string(&1) == key))

    cond do
      known != nil and value == nil ->
        "#{name} needs a value: #{Map.get(accepted, known, describe(switches[known]))}"

      known != nil ->
        "#{name} takes #{Map.get(accepted, known, describe(switches[known]))}, got: #{value}"

      true ->
        case suggest(name, switches) do
          nil -> "unknown option #{name} (see --help)"
          best -> "unknown option #{name} (did you mean #{best}?)"
        end
    end
  end

  defp describe(:integer), do: "an integer"
  defp describe(:float), do: "a number"
  defp describe(_), do: "a value"

  @doc """
  The known switch closest to `name`, as `--switch`, if one is close.

      iex> RingTracer.CLI.Args.suggest("--widht", width: :integer, height: :integer)
      "--width"
      iex> RingTracer.CLI.Args.suggest("--zzz", width: :integer)
      nil
  """
  @spec suggest(String.t(), keyword()) :: String.t() | nil
  def suggest(name, switches) do
    typed = String.trim_leading(name, "-")

    switches
    |> Keyword.keys()
    |> Enum.map(&String.replace(Atom.to_string(&1), "_", "-"))
    |> Enum.map(&{String.jaro_distance(typed, &1), &1})
    |> Enum.max(fn -> {0.0, nil} end)
    |> case do
      {score, best} when score >= 0.8 -> "--" <> best
      _ -> nil
    end
  end

  @doc """
  Checks that the integer option `key`, if given, lies in `range`.

      iex> RingTracer.CLI.Args.in_range([depth: 99], :depth, 1..64)
      {:error, "--depth takes an integer from 1 to 64, got: 99"}
      iex> RingTracer.CLI.Args.in_range([depth: 9], :depth, 1..64)
      :ok
  """
  @spec in_range(keyword(), atom(), Range.t()) :: :ok | {:error, String.t()}
  def in_range(opts, key, first..last//1 = range) do
    case opts[key] do
      nil ->
        :ok

      v ->
        if v in range,
          do: :ok,
          else: {:error, "#{flag(key)} takes an integer from #{first} to #{last}, got: #{v}"}
    end
  end

  @doc "`key` as the switch a user types."
  @spec flag(atom()) :: String.t()
  def flag(key), do: "--" <> String.replace(Atom.to_string(key), "_", "-")
end
