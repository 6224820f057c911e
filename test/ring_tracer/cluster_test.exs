defmodule RingTracer.ClusterTest do
  use ExUnit.Case, async: true
  doctest RingTracer.Cluster

  alias RingTracer.Cluster

  describe "hosts_our_children?/1" do
    # A pid of a process on node `name`, as the distribution would decode it.
    defp remote_pid(name) do
      name = Atom.to_string(name)
      :erlang.binary_to_term(<<131, 88, 119, byte_size(name), name::binary, 7::32, 0::32, 1::32>>)
    end

    test "only a node with a child of a job here is this node's news (its node-down line)" do
      {:ok, _} = Application.ensure_all_started(:ring_tracer)
      refute Cluster.hosts_our_children?(:w9@ours)

      parent = spawn(fn -> receive do: (:stop -> :ok) end)
      ring = {self(), remote_pid(:w9@ours)}
      id = make_ref()
      :ok = RingTracer.Job.Directory.publish(node(), id, parent, ring)
      :ok = RingTracer.Job.Directory.await(id, 2, 5_000)
      assert Cluster.hosts_our_children?(:w9@ours)
      # another render's VM, met through a shared worker
      refute Cluster.hosts_our_children?(:render2@theirs)

      ref = Process.monitor(parent)
      send(parent, :stop)
      assert_receive {:DOWN, ^ref, _, _, _}
      # the directory drops the job's rows once its parent is gone
      _ = RingTracer.Job.Directory.jobs()
      refute Cluster.hosts_our_children?(:w9@ours)
    end
  end

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
