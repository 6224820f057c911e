defmodule RingTracer.Scene.Source do
  @moduledoc """
  A scene as bytes, ready to ship to another node: its file name, format,
  contents, the contents of every file it references, and a content hash
  that names it in each node's `RingTracer.SceneCache`.
  """

  @enforce_keys [:name, :format, :bytes, :includes, :hash]
  defstruct [:name, :format, :bytes, :includes, :hash]

  @type t :: %__MODULE__{
          name: String.t(),
          format: String.t(),
          bytes: binary() | nil,
          includes: %{String.t() => binary()},
          hash: binary()
        }

  @doc "A source with its content hash."
  @spec new(String.t(), String.t(), binary(), %{String.t() => binary()}) :: t()
  def new(name, format, bytes, includes) do
    hash =
      includes
      |> Enum.sort()
      |> Enum.reduce(:crypto.hash_init(:sha256) |> :crypto.hash_update([format, 0, bytes]), fn
        {k, v}, acc -> :crypto.hash_update(acc, [0, k, 0, <<byte_size(v)::64>>, v])
      end)
      |> :crypto.hash_final()

    %__MODULE__{name: name, format: format, bytes: bytes, includes: includes, hash: hash}
  end

  @doc """
  The source without its contents: what children receive, once the scene is
  cached on their node, so that the bytes travel once per node, not per child.
  """
  @spec strip(t()) :: t()
  def strip(%__MODULE__{} = source), do: %{source | bytes: nil, includes: %{}}

  @doc "Total bytes shipped with this source."
  @spec size(t()) :: non_neg_integer()
  def size(%__MODULE__{bytes: bytes, includes: includes}) do
    Enum.reduce(includes, byte_size(bytes), fn {_, v}, acc -> acc + byte_size(v) end)
  end
end
