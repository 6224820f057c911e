defmodule RingTracer.CLI.Server.Device do
  @moduledoc false
  # An I/O device (OTP's I/O protocol) that sends what is written to a
  # client's socket as frames tagged `tag` (stdout or stderr). Requests are
  # answered once the frame is sent, so when a command returns all it wrote
  # has reached the socket.

  @doc "A device for `socket`, tagged `tag`, that stops with `owner`."
  @spec start(:gen_tcp.socket(), String.t(), boolean(), pid()) :: pid()
  def start(socket, tag, tty?, owner) do
    spawn(fn ->
      ref = Process.monitor(owner)
      loop(%{socket: socket, tag: tag, tty?: tty?, ref: ref})
    end)
  end

  defp loop(state) do
    receive do
      {:io_request, from, reply_as, request} ->
        send(from, {:io_reply, reply_as, request(request, state)})
        loop(state)

      {:DOWN, ref, _, _, _} when ref == state.ref ->
        :ok
    end
  end

  defp request({:put_chars, encoding, chars}, state) do
    case :unicode.characters_to_binary(chars, encoding, :unicode) do
      bin when is_binary(bin) -> put(bin, state)
      _ -> {:error, :put_chars}
    end
  end

  defp request({:put_chars, encoding, m, f, a}, state),
    do: request({:put_chars, encoding, apply(m, f, a)}, state)

  defp request({:put_chars, chars}, state), do: request({:put_chars, :latin1, chars}, state)
  defp request({:put_chars, m, f, a}, state), do: request({:put_chars, :latin1, m, f, a}, state)

  defp request({:get_geometry, :columns}, %{tty?: true}), do: 80
  defp request({:get_geometry, _}, _state), do: {:error, :enotsup}
  defp request({:setopts, _}, _state), do: :ok
  defp request(:getopts, _state), do: [binary: true, encoding: :unicode]

  defp request({:requests, requests}, state) do
    Enum.reduce_while(requests, :ok, fn r, _ ->
      case request(r, state) do
        :ok -> {:cont, :ok}
        other -> {:halt, other}
      end
    end)
  end

  defp request(_other, _state), do: {:error, :request}

  defp put("", _state), do: :ok

  defp put(bin, state) do
    # A client that went away loses its output; the session cancels its job.
    _ = :gen_tcp.send(state.socket, [state.tag, bin])
    :ok
  end
end
