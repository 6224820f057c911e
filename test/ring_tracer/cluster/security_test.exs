defmodule RingTracer.Cluster.SecurityTest do
  # Real OS processes: a worker booted the way the launcher boots it, and
  # a second Unix user playing the local attacker.
  use ExUnit.Case, async: false

  @moduletag :distributed
  @moduletag :tmp_dir
  @moduletag timeout: 120_000

  alias RingTracer.Cluster.{Cookie, TLS}
  alias RingTracer.Test.{OSNode, SecondUser}

  @attacker "rtattacker"

  setup_all do
    RingTracer.LocalCluster.ensure_distributed()
    {:ok, attacker: attacker()}
  end

  setup %{tmp_dir: dir} do
    File.chmod!(dir, 0o755)
    cookie_file = Path.join(dir, "cookie")
    {:ok, _} = Cookie.create(cookie_file)
    {:ok, cookie} = Cookie.read(cookie_file)
    {:ok, cookie_file: cookie_file, cookie: cookie}
  end

  defp sname, do: "wsec_#{System.unique_integer([:positive])}"

  # The flags the launcher boots a worker with: TLS with this user's own
  # certificates (this test's VM was booted with them too).
  defp tls, do: [vm_args: TLS.vm_args(TLS.booted_dir())]

  defp start_worker!(args) do
    worker = OSNode.start(["worker" | args], tls())
    {:ok, worker} = OSNode.await(worker, "ready")
    on_exit(fn -> OSNode.stop(worker) end)
    worker
  end

  # A second user for the attacker (root in CI can make one); nil where
  # that is not possible.
  defp attacker do
    with {"0\n", 0} <- System.cmd("id", ["-u"]),
         :ok <- SecondUser.ensure(@attacker) do
      @attacker
    else
      _ -> nil
    end
  end

  defp as_attacker(user, command) do
    System.cmd("runuser", ["-u", user, "--" | command], stderr_to_stdout: true)
  end

  test "the cookie is on no command line, in no environment, and the file is private", %{
    attacker: attacker,
    cookie_file: cookie_file,
    cookie: cookie
  } do
    if attacker == nil, do: flunk("needs root to create a second user for the attacker")
    name = sname()
    worker = start_worker!(["--sname", name, "--cookie-file", cookie_file])
    secret = Atom.to_string(cookie)

    {cmdline, 0} = as_attacker(attacker, ["cat", "/proc/#{worker.os_pid}/cmdline"])
    assert cmdline =~ "--cookie-file"
    refute cmdline =~ secret

    {environ, _} = as_attacker(attacker, ["cat", "/proc/#{worker.os_pid}/environ"])
    refute environ =~ secret

    {denied, status} = as_attacker(attacker, ["cat", cookie_file])
    assert status != 0
    assert denied =~ "Permission denied"

    # The owner, who has the file, gets in: the cookie is really the one in use.
    node = :"#{name}@localhost"
    Node.set_cookie(node, cookie)
    assert Node.connect(node)
    assert :erpc.call(node, :erlang, :node, []) == node
    Node.disconnect(node)
  end

  test "--cookie is refused, and so is a cookie file others can read", %{
    cookie_file: cookie_file
  } do
    {status, output} =
      OSNode.wait_exit(OSNode.start(["worker", "--sname", sname(), "--cookie", "c"], tls()))

    assert status == 1
    assert output =~ "--cookie-file"

    File.chmod!(cookie_file, 0o644)

    {status, output} =
      OSNode.wait_exit(
        OSNode.start(["worker", "--sname", sname(), "--cookie-file", cookie_file], tls())
      )

    assert status == 1
    assert output =~ "can be read by other users"
    assert output =~ "chmod 600 #{cookie_file}"
  end

  test "the worker and epmd listen on loopback only", %{cookie_file: cookie_file} do
    worker = start_worker!(["--sname", sname(), "--cookie-file", cookie_file])
    {ss, 0} = System.cmd("ss", ["-ltnpH"])

    listening =
      for line <- String.split(ss, "\n", trim: true),
          String.contains?(line, "pid=#{worker.os_pid},") or String.contains?(line, "\"epmd\""),
          do: line |> String.split() |> Enum.at(3)

    assert Enum.any?(listening, &String.ends_with?(&1, ":4369"))
    assert length(listening) >= 2

    for address <- listening do
      assert address =~ ~r/^(127\.0\.0\.1|\[::1\]):\d+$/, "listening on #{address}"
    end
  end

  test "a name in use is a clear error", %{cookie_file: cookie_file} do
    name = sname()
    _first = start_worker!(["--sname", name, "--cookie-file", cookie_file])

    {status, output} =
      OSNode.wait_exit(
        OSNode.start(["worker", "--sname", name, "--cookie-file", cookie_file], tls())
      )

    assert status == 1
    assert output =~ "the node name #{name} is in use"
  end
end
