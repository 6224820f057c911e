defmodule RingTracer.ClusterTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Cluster

  alias RingTracer.Cluster

  describe "call_failure/3" do
    test "a call's exit when its node drops or is disconnected reads as a lost connection" do
      call = {GenServer, :call, [{RingTracer.Children, :w1@host}, :which_children, :infinity]}

      for reason <- [
            {:erpc, :noconnection},
            :noconnection,
            {:nodedown, :w1@host},
            {:noconnection, call},
            {{:nodedown, :w1@host}, call}
          ] do
        assert Cluster.call_failure(:w1@host, reason, :infinity) =~
                 "lost the connection to node w1@host",
               inspect(reason)
      end
    end

    test "anything else is named as it is" do
      assert Cluster.call_failure(:w1@host, {:erpc, :notsup}, 5_000) ==
               "node w1@host: {:erpc, :notsup}"
    end
  end
end
