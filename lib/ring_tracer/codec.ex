defmodule RingTracer.Codec do
  @moduledoc false
  # Plain zstd frames (the `zstd` crate, through the NIF), for what a job
  # sends compressed besides its pixels (`RingTracer.Pixels`): a scene
  # shipped to a node. Both run on a dirty CPU scheduler.

  alias RingTracer.{Error, Native}

  @doc "`bytes` as one zstd frame."
  @spec compress(binary()) :: {:ok, binary()} | {:error, Error.t()}
  def compress(bytes) when is_binary(bytes) do
    case Native.zstd_compress(bytes) do
      {:ok, frame} -> {:ok, frame}
      {:error, message} -> {:error, Error.new(:invalid_option, message)}
    end
  end

  @doc """
  The bytes of zstd frames, at most `max_bytes` of them: more, or a frame
  that is not zstd, is an error (`:reason` `:corrupt`), never a crash.
  """
  @spec decompress(binary(), non_neg_integer()) :: {:ok, binary()} | {:error, Error.t()}
  def decompress(frames, max_bytes)
      when is_binary(frames) and is_integer(max_bytes) and max_bytes >= 0 do
    case Native.zstd_decompress(frames, max_bytes) do
      {:ok, bytes} -> {:ok, bytes}
      {:error, message} -> {:error, Error.new(:corrupt, message)}
    end
  end
end
