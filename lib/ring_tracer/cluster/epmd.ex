defmodule RingTracer.Cluster.Epmd do
  @moduledoc false
  # Who listens on epmd's port: the kernel's socket tables
  # (/proc/net/tcp and /proc/net/tcp6, of this process's network
  # namespace) carry the address and the owner's uid of every listening
  # socket. A node asks epmd for the port of every node it connects to,
  # so an epmd of another user can point it at a relay of hers.

  @port 4369
  @listen_state "0A"

  @typedoc "A socket listening on epmd's port: its address and its owner."
  @type listener :: %{address: :inet.ip_address(), uid: non_neg_integer()}

  @doc "epmd's port."
  @spec port() :: pos_integer()
  def port, do: @port

  @doc """
  The sockets listening on `port` in this network namespace, or `:unknown`
  when the kernel's tables cannot be read.
  """
  @spec listeners(pos_integer()) :: [listener()] | :unknown
  def listeners(port \\ @port) do
    tables =
      for file <- ["/proc/net/tcp", "/proc/net/tcp6"],
          {:ok, text} <- [File.read(file)],
          do: text

    if tables == [],
      do: :unknown,
      else: Enum.flat_map(tables, &parse(&1, port))
  end

  @doc """
  The listening sockets of one table's text (the format of /proc/net/tcp).

      iex> RingTracer.Cluster.Epmd.parse(
      ...>   "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode\\n" <>
      ...>   "   0: 0100007F:1111 00000000:0000 0A 00000000:00000000 00:00000000 00000000  1001        0 1 1 0\\n" <>
      ...>   "   1: 0100007F:1F90 00000000:0000 0A 00000000:00000000 00:00000000 00000000     0        0 2 1 0\\n",
      ...>   4369)
      [%{address: {127, 0, 0, 1}, uid: 1001}]
  """
  @spec parse(String.t(), pos_integer()) :: [listener()]
  def parse(text, port) do
    for line <- text |> String.split("\n", trim: true) |> Enum.drop(1),
        [_sl, local, _remote, @listen_state, _, _, _, uid | _] <- [String.split(line)],
        [hex_ip, hex_port] <- [String.split(local, ":")],
        {^port, ""} <- [Integer.parse(hex_port, 16)],
        {:ok, address} <- [address(hex_ip)],
        {uid, ""} <- [Integer.parse(uid)],
        do: %{address: address, uid: uid}
  end

  # The kernel prints each 32-bit word of the address in the host's byte order.
  defp address(hex) do
    case Base.decode16(hex, case: :mixed) do
      {:ok, <<_::binary-size(4)>> = bytes} ->
        {:ok, bytes |> words() |> :erlang.list_to_tuple()}

      {:ok, <<_::binary-size(16)>> = bytes} ->
        <<a::16, b::16, c::16, d::16, e::16, f::16, g::16, h::16>> =
          bytes |> words() |> :erlang.list_to_binary()

        {:ok, {a, b, c, d, e, f, g, h}}

      _ ->
        :error
    end
  end

  defp words(bytes) do
    for <<word::binary-size(4) <- bytes>>, into: [] do
      if :erlang.system_info(:endian) == :little,
        do: word |> :binary.bin_to_list() |> Enum.reverse(),
        else: :binary.bin_to_list(word)
    end
    |> List.flatten()
  end

  @doc "This OS process's uid (the owner of /proc/self)."
  @spec own_uid() :: non_neg_integer()
  def own_uid do
    %File.Stat{uid: uid} = File.stat!("/proc/self")
    uid
  end

  @doc """
  The listeners that belong to neither this user nor root (root can read
  every process's memory anyway, so its epmd is trusted).
  """
  @spec foreign([listener()], non_neg_integer()) :: [listener()]
  def foreign(listeners, uid), do: Enum.reject(listeners, &(&1.uid in [uid, 0]))

  @doc """
  A user's name from /etc/passwd, or `uid N` when it has none there.

      iex> RingTracer.Cluster.Epmd.user_name(0)
      "root"
  """
  @spec user_name(non_neg_integer()) :: String.t()
  def user_name(uid) do
    with {:ok, text} <- File.read("/etc/passwd"),
         [name | _] <-
           for(
             line <- String.split(text, "\n"),
             [name, _, id | _] <- [String.split(line, ":")],
             id == Integer.to_string(uid),
             do: name
           ) do
      name
    else
      _ -> "uid #{uid}"
    end
  end

  @doc "Describes listeners for a message: `user mallory (uid 1001) on 127.0.0.1`."
  @spec describe([listener()]) :: String.t()
  def describe(listeners) do
    listeners
    |> Enum.group_by(& &1.uid, & &1.address)
    |> Enum.map_join("; ", fn {uid, addresses} ->
      "user #{user_name(uid)} (uid #{uid}) on " <>
        Enum.map_join(Enum.uniq(addresses), ", ", &to_string(:inet.ntoa(&1)))
    end)
  end
end
