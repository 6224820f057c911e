defmodule RingTracer.Bench.Network.Epmd do
  @moduledoc false
  # The port mapper of the nodes in the network benchmark's namespaces
  # (`RingTracer.Bench.Network.Lab`), given to their VMs with
  # `-epmd_module Elixir.RingTracer.Bench.Network.Epmd`.
  #
  # No epmd runs in the namespaces. Each node knows the whole (fixed) map
  # of the benchmark's nodes, put in `:persistent_term` by `configure/1`
  # before the node starts distribution:
  #
  #   * its own listen port (`listen_port_please/2`), on the address that
  #     `inet_dist_use_interface` names;
  #   * for every other node, the address and port where the delaying relay
  #     listens on this node's link for connections to that node
  #     (`address_please/3`). Every distribution connection therefore goes
  #     through the relay, which adds the one-way delay.
  #
  # A name that is not in the map is unknown (`{:error, :nxdomain}`).

  # The distribution protocol version that OTP 23 and later speak.
  @version 6

  @typedoc "The map one node uses: its own port, and where to reach each other node."
  @type config :: %{port: :inet.port_number(), routes: %{String.t() => {tuple(), pos_integer()}}}

  @doc "Puts this node's map in place; call it before `Node.start/2`."
  @spec configure(config()) :: :ok
  def configure(%{port: _, routes: _} = config), do: :persistent_term.put(__MODULE__, config)

  @doc false
  @spec start_link() :: :ignore
  def start_link, do: :ignore

  @doc false
  def register_node(_name, _port), do: {:ok, creation()}
  @doc false
  def register_node(_name, _port, _family), do: {:ok, creation()}

  @doc false
  def listen_port_please(_name, _host), do: {:ok, config().port}

  @doc false
  def port_please(name, _host), do: port_please(name, nil, :infinity)

  @doc false
  def port_please(name, _host, _timeout) do
    case route(name) do
      {_ip, port} -> {:port, port, @version}
      nil -> :noport
    end
  end

  @doc false
  def address_please(name, _host, _family) do
    case route(name) do
      {ip, port} -> {:ok, ip, port, @version}
      nil -> {:error, :nxdomain}
    end
  end

  @doc false
  def names(_host) do
    {:ok, for({name, {_ip, port}} <- config().routes, do: {String.to_charlist(name), port})}
  end

  defp route(name), do: Map.get(config().routes, to_string(name))

  defp config, do: :persistent_term.get(__MODULE__, %{port: 0, routes: %{}})

  # A node's incarnation; any value but 0 will do for nodes that never
  # restart under the same name.
  defp creation, do: :rand.uniform(0xFFFF_FFF0) + 3
end
