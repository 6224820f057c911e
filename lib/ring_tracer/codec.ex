defmodule RingTracer.Codec do
  @moduledoc false
  # Plain zstd frames (the `zstd` crate, through the NIF: `native/wire`),
  # for what a job sends compressed besides its pixels
  # (`RingTracer.Pixels`): a scene shipped to a node
  # (`RingTracer.Scene.Source.pack/1`). Both run on a dirty CPU scheduler.

  alias RingTracer.Native

  @doc "`binary` as one zstd frame (level 3)."
  @spec compress(binary()) :: binary()
  def compress(binary) when is_binary(binary) do
    case Native.zstd_compress(binary) do
      {:ok, frame} -> frame
      {:error, message} -> raise RingTracer.Error.new(:render_failed, "zstd: #{message}")
    end
  end

  @doc """
  The bytes of zstd frames, at most `max` of them: more, or data that is
  not zstd frames, is an error that says so, never a crash.
  """
  @spec decompress(binary(), non_neg_integer()) :: {:ok, binary()} | {:error, String.t()}
  def decompress(binary, max) when is_binary(binary) and is_integer(max) and max >= 0,
    do: Native.zstd_decompress(binary, max)
end
