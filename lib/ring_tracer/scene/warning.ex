defmodule RingTracer.Scene.Warning do
  @moduledoc """
  Something in a scene file that parses and renders, but maybe not as its
  author meant: a zero-radius sphere that shows nothing, a colour outside
  [0, 1], an OBJ face whose material is not in its MTL. Input that cannot
  mean what it says is an error instead, and the scene does not load (the
  table of which is which, and why, is in `docs/scene-format.md`).

  A loaded `RingTracer.Scene` holds its warnings (`:warnings`, at most 100,
  in the order found, and `:warnings_omitted`, how many more there were), and
  so does the `RingTracer.Result` of a render. Nothing is printed or logged
  by the library; `mix ring_tracer.render` prints them to stderr before it
  renders.

      iex> w = %RingTracer.Scene.Warning{file: "a.nff", line: 12, message: "sphere 's' has radius 0 and is not rendered"}
      iex> to_string(w)
      "a.nff:12: warning: sphere 's' has radius 0 and is not rendered"
      iex> to_string(%{w | line: nil})
      "a.nff: warning: sphere 's' has radius 0 and is not rendered"
  """

  @enforce_keys [:file, :line, :message]
  defstruct [:file, :line, :message]

  @typedoc """
  `:file` is the file it is about (the scene, or a mesh or material library
  it references, as written); `:line` counts from 1, `nil` for the file as a
  whole.
  """
  @type t :: %__MODULE__{
          file: String.t(),
          line: pos_integer() | nil,
          message: String.t()
        }

  @doc false
  @spec from_native(%{file: String.t(), line: pos_integer() | nil, message: String.t()}) :: t()
  def from_native(%{file: file, line: line, message: message}),
    do: %__MODULE__{file: file, line: line, message: message}

  @doc """
  The lines a command prints for `warnings`, `file:line: warning: message`
  each, and one more that counts the `omitted` ones.

      iex> w = %RingTracer.Scene.Warning{file: "a.nff", line: 3, message: "m"}
      iex> RingTracer.Scene.Warning.lines([w], 2)
      ["a.nff:3: warning: m", "warning: 2 more warnings not shown"]
      iex> RingTracer.Scene.Warning.lines([], 0)
      []
  """
  @spec lines([t()], non_neg_integer()) :: [String.t()]
  def lines(warnings, omitted) do
    more =
      case omitted do
        0 -> []
        1 -> ["warning: 1 more warning not shown"]
        n -> ["warning: #{n} more warnings not shown"]
      end

    Enum.map(warnings, &to_string/1) ++ more
  end

  defimpl String.Chars do
    def to_string(%{file: file, line: nil, message: message}),
      do: "#{file}: warning: #{message}"

    def to_string(%{file: file, line: line, message: message}),
      do: "#{file}:#{line}: warning: #{message}"
  end
end
