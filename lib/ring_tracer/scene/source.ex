defmodule RingTracer.Scene.Source do
  @moduledoc false
  # A scene as bytes, ready to ship to another node: its file name, format,
  # contents, the contents of every file it references, and a content hash
  # that names it in each node's `RingTracer.SceneCache`.

  @enforce_keys [:name, :format, :bytes, :includes, :hash]
  defstruct [:name, :format, :bytes, :includes, :hash, packed: nil]

  @typedoc """
  A scene's source: `bytes` and `includes` its contents (nil and empty
  once stripped), `packed` its contents compressed (`pack/1`) on the way
  to a node that lacks them.
  """
  @type t :: %__MODULE__{
          name: String.t(),
          format: String.t(),
          bytes: binary() | nil,
          includes: %{String.t() => binary()},
          hash: binary(),
          packed: binary() | nil
        }

  # The most bytes a packed source may unpack to.
  @max_unpacked 1_073_741_824

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
  def strip(%__MODULE__{} = source), do: %{source | bytes: nil, includes: %{}, packed: nil}

  @doc """
  The source with its contents compressed into one binary: what a node
  that does not hold the scene receives (`unpack/1` restores it there).
  """
  @spec pack(t()) :: t()
  def pack(%__MODULE__{bytes: bytes, includes: includes} = source) when is_binary(bytes) do
    packed = RingTracer.Codec.compress(:erlang.term_to_binary({bytes, includes}))
    %{strip(source) | packed: packed}
  end

  @doc """
  A packed source with its contents restored, checked against its content
  hash; any other source as it is.
  """
  @spec unpack(t()) :: {:ok, t()} | {:error, String.t()}
  def unpack(%__MODULE__{packed: nil} = source), do: {:ok, source}

  def unpack(%__MODULE__{packed: packed, name: name, hash: hash} = source) do
    with {:ok, binary} <- RingTracer.Codec.decompress(packed, @max_unpacked),
         {bytes, includes} when is_binary(bytes) and is_map(includes) <- safe_term(binary),
         %__MODULE__{hash: ^hash} = unpacked <- new(name, source.format, bytes, includes) do
      {:ok, unpacked}
    else
      _ -> {:error, "scene #{name} arrived damaged: its contents do not match its hash"}
    end
  end

  defp safe_term(binary) do
    :erlang.binary_to_term(binary, [:safe])
  rescue
    ArgumentError -> :error
  end

  @doc "The bytes of a packed source's contents (0 for any other)."
  @spec packed_size(t()) :: non_neg_integer()
  def packed_size(%__MODULE__{packed: nil}), do: 0
  def packed_size(%__MODULE__{packed: packed}), do: byte_size(packed)

  @doc "Total bytes shipped with this source."
  @spec size(t()) :: non_neg_integer()
  def size(%__MODULE__{bytes: bytes, includes: includes}) do
    Enum.reduce(includes, byte_size(bytes), fn {_, v}, acc -> acc + byte_size(v) end)
  end
end
