defmodule RingTracer.Cluster.DistributionTest do
  use ExUnit.Case, async: true

  alias RingTracer.Cluster.{Distribution, TLS}

  describe "transport" do
    test "TLS when the VM was booted with it; plain only when asked, and never both" do
      # bin/ringtracer boots Mix's VMs with TLS distribution.
      if TLS.enabled?() do
        assert Distribution.transport([]) == {:ok, :tls}
        assert {:error, %{message: message}} = Distribution.transport(insecure_plain: true)
        assert message =~ "booted with TLS"
      else
        assert {:error, %{message: message}} = Distribution.transport([])
        assert message =~ "--insecure-plain"
        assert Distribution.transport(insecure_plain: true) == {:ok, :plain}
      end

      assert {:error, %{message: message}} =
               Distribution.transport(tls: "/nowhere", insecure_plain: true)

      assert message =~ "exclude each other"
    end
  end

  describe "node names" do
    test "bad names are refused in one line, naming the flag" do
      for {opts, text} <- [
            {[sname: "a.b"], "--sname: a node name is letters"},
            {[sname: "w1@a.b"], "a short name's host is one word without dots"},
            {[sname: "a@b@c"], "at most one @"},
            {[name: "w1"], "--name takes NAME@HOST"},
            {[name: "w1@a b"], "must be a host name"},
            {[name: "@host.example"], "--name: a node name is letters"}
          ] do
        assert {:error, %RingTracer.Error{reason: :invalid_option, message: message}} =
                 Distribution.node_name(opts, {127, 0, 0, 1})

        assert message =~ text, inspect(opts)
        refute message =~ "\n"
      end
    end

    test "good names pass" do
      assert {:ok, "w1@box", :shortnames} =
               Distribution.node_name([sname: "w1@box"], {127, 0, 0, 1})

      assert {:ok, "w1", :shortnames} = Distribution.node_name([sname: "w1"], {10, 0, 0, 5})

      assert {:ok, "w-1_a@w1.example.org", :longnames} =
               Distribution.node_name([name: "w-1_a@w1.example.org"], {10, 0, 0, 5})

      assert {:ok, "w1@::1", :longnames} = Distribution.node_name([name: "w1@::1"], {0, 0, 0, 0})
    end
  end

  test "while a start runs, OTP's reports of it are dropped and nothing else is" do
    alias RingTracer.Cluster.Distribution
    starting = :atomics.new(1, [])
    sasl = %{level: :error, msg: {:string, ~c"x"}, meta: %{domain: [:otp, :sasl]}}
    legacy = %{level: :notice, msg: {:string, ~c"x"}, meta: %{error_logger: %{tag: :info_msg}}}
    ours = %{level: :warning, msg: {:string, ~c"x"}, meta: %{domain: [:elixir]}}

    # No start under way: every event goes on.
    for e <- [sasl, legacy, ours],
        do: assert(Distribution.drop_start_reports(e, starting) == :ignore)

    :atomics.add(starting, 1, 1)
    assert Distribution.drop_start_reports(sasl, starting) == :stop
    assert Distribution.drop_start_reports(legacy, starting) == :stop
    assert Distribution.drop_start_reports(ours, starting) == :ignore
  end
end
