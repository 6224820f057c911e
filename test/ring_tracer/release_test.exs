defmodule RingTracer.ReleaseTest do
  # `bin/ringtracer release`'s tarball, unpacked and run where Erlang,
  # Elixir and Rust are not: a mount namespace of the command's own
  # (unshare -m) with empty folders mounted over their installs. It renders
  # the image the checkout renders, it hosts the children of a render the
  # checkout runs, and it works for a checkout's farm head. Needs root (and
  # unshare); skipped, saying why, elsewhere.
  use ExUnit.Case, async: true

  import Bitwise, only: [&&&: 2]
  import RingTracer.Test.PortOutput, only: [collect: 1, until: 2]

  alias RingTracer.Cluster.{Cookie, TLS}

  @moduletag :release
  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  @launcher Path.expand("bin/ringtracer")
  @scene Path.expand("priv/scenes/balls_s2.nff")
  # What a machine without Erlang, Elixir or Rust lacks.
  @hidden_dirs ["/usr/lib/erlang", "/usr/lib/elixir"] ++
                 Enum.map([".cargo", ".rustup"], &Path.join(System.user_home!(), &1))
  @hidden_commands ~w(erl erlc escript epmd elixir elixirc iex mix cargo rustc rustup)

  @probe (cond do
            System.find_executable("unshare") == nil ->
              {:error, "unshare (util-linux) is not installed"}

            match?({"0\n", 0}, System.cmd("id", ["-u"])) == false ->
              {:error, "not root: mounting over Erlang's install needs it"}

            match?({_, 0}, System.cmd("unshare", ["-m", "true"], stderr_to_stdout: true)) ->
              :ok

            true ->
              {:error, "unshare -m fails here (no mount namespaces)"}
          end)
  if @probe != :ok do
    {:error, why} = @probe
    IO.puts(:stderr, "release test skipped: #{why}")
    @moduletag skip: "the release test cannot hide Erlang here: #{why}"
  end

  # One tarball for the module, unpacked once.
  setup_all do
    dir = Path.join(System.tmp_dir!(), "rt_release_#{System.unique_integer([:positive])}")
    File.mkdir_p!(Path.join(dir, "empty"))
    File.write!(Path.join(dir, "empty_file"), "")
    on_exit(fn -> File.rm_rf!(dir) end)

    {started, _} = :erlang.statistics(:wall_clock)
    # Ten minutes at most: a stale checkout builds the NIF and the application first.
    {out, status} =
      System.cmd("timeout", ["-k", "10", "600", @launcher, "release", "--out", dir],
        stderr_to_stdout: true
      )

    assert status == 0, out
    [tarball] = Path.wildcard(Path.join(dir, "ringtracer-*-linux-*.tar.gz"))
    {_, 0} = System.cmd("timeout", ["60", "tar", "-C", dir, "-xzf", tarball])
    # One folder, ringtracer-VERSION.
    root = Path.join(dir, String.replace(Path.basename(tarball), ~r/-linux-.*$/, ""))
    {ended, _} = :erlang.statistics(:wall_clock)
    IO.puts(:stderr, "release test: tarball built and unpacked in #{ended - started} ms")
    {:ok, dir: dir, tarball: tarball, release: Path.join(root, "bin/ringtracer")}
  end

  # The release's launcher (or any command) in a new mount namespace where
  # the installs are hidden: every hidden command must be gone (exit 97
  # otherwise, naming it).
  defp hidden(ctx, args, opts \\ []) do
    mounts =
      for d <- @hidden_dirs, File.dir?(d), do: "mount --bind #{ctx.dir}/empty #{d} || exit 96\n"

    script =
      Enum.join(mounts) <>
        """
        for c in #{Enum.join(@hidden_commands, " ")}; do
          if p=$(command -v "$c"); then
            [ -e "$p" ] && mount --bind #{ctx.dir}/empty_file "$p"
            if [ -x "$p" ] && [ -s "$p" ]; then echo "still installed: $c ($p)"; exit 97; fi
          fi
        done
        exec "$@"
        """

    open(
      ctx,
      "unshare",
      ["-m", "--propagation", "private", "--", "sh", "-c", script, "sh"] ++ args,
      opts
    )
  end

  defp open(ctx, command, args, opts) do
    Port.open({:spawn_executable, System.find_executable(command)}, [
      :binary,
      :exit_status,
      :stderr_to_stdout,
      args: args,
      cd: Keyword.get(opts, :cd, ctx.tmp_dir),
      env: [
        {~c"RINGTRACER_SERVER", ~c"off"},
        {~c"XDG_CONFIG_HOME", String.to_charlist(ctx.tmp_dir)}
      ]
    ])
  end

  defp checkout(ctx, args), do: collect(open(ctx, @launcher, args, []))

  test "without Erlang, Elixir or Rust: --version, help, a usage error, cookie, tls and a render identical to the checkout's",
       ctx do
    {status, out} = collect(hidden(ctx, ["sh", "-c", "command -v erl elixir cargo; echo none"]))
    assert {status, out} == {0, "none\n"}

    {status, version} = collect(hidden(ctx, [ctx.release, "--version"]))
    assert status == 0, version
    assert version =~ ~r/^ringtracer (\d+\.\d+\.\d+) \(build \1\+[0-9a-f]{8}\)\n$/
    assert checkout(ctx, ["--version"]) == {0, version}

    assert collect(hidden(ctx, [ctx.release, "render", "--help"])) ==
             checkout(ctx, ["render", "--help"])

    {status, usage} = collect(hidden(ctx, [ctx.release, "render"]))
    assert status == 2, usage
    assert checkout(ctx, ["render"]) == {2, usage}

    {status, out} = collect(hidden(ctx, [ctx.release, "cookie", "release.cookie"]))
    assert status == 0, out
    assert out =~ "(mode 0600)"
    assert (File.stat!(Path.join(ctx.tmp_dir, "release.cookie")).mode &&& 0o777) == 0o600

    {status, out} = collect(hidden(ctx, [ctx.release, "tls", "ca", "ca"]))
    assert status == 0, out
    {status, out} = collect(hidden(ctx, [ctx.release, "tls", "node", "ca", "node", "localhost"]))
    assert status == 0, out

    for file <- ~w(ca.pem node.pem node.key),
        do: assert(File.regular?(Path.join([ctx.tmp_dir, "node", file])))

    size = ~w(--width 64 --children 2 --progress none)

    {status, out} =
      collect(hidden(ctx, [ctx.release, "render", @scene, "--out", "release.png" | size]))

    assert status == 0, out
    {status, out} = checkout(ctx, ["render", @scene, "--out", "checkout.png" | size])
    assert status == 0, out

    assert File.read!(Path.join(ctx.tmp_dir, "release.png")) ==
             File.read!(Path.join(ctx.tmp_dir, "checkout.png"))
  end

  test "a release worker hosts children of the checkout's render over TLS; the image is the same",
       ctx do
    cookie = Path.join(ctx.tmp_dir, "cookie")
    {:ok, _} = Cookie.create(cookie)
    tls = TLS.booted_dir()
    w = "rtrel_#{System.unique_integer([:positive])}"

    worker =
      hidden(ctx, [ctx.release, "worker", "--sname", w, "--cookie-file", cookie, "--tls", tls])

    {:os_pid, worker_pid} = Port.info(worker, :os_pid)

    # SIGTERM reaches the VM through its launcher (SIGKILL would leave it running).
    on_exit(fn ->
      System.cmd("kill", ["-TERM", Integer.to_string(worker_pid)], stderr_to_stdout: true)
    end)

    assert until(worker, "ready") =~ "RingTracer worker #{w}@"

    size = ~w(--width 48 --children 4 --progress none)

    {status, out} =
      checkout(
        ctx,
        ["render", @scene, "--out", "cluster.png", "--nodes", "#{w}@localhost"] ++
          ["--cookie-file", cookie, "--tls", tls | size]
      )

    assert status == 0, out
    assert out =~ "on #{w}@localhost"
    {status, out} = checkout(ctx, ["render", @scene, "--out", "alone.png" | size])
    assert status == 0, out

    assert File.read!(Path.join(ctx.tmp_dir, "cluster.png")) ==
             File.read!(Path.join(ctx.tmp_dir, "alone.png"))

    # SIGTERM: the worker leaves and exits 143, as the checkout's does.
    {_, 0} = System.cmd("kill", ["-TERM", Integer.to_string(worker_pid)])
    assert {143, _} = collect(worker)
  end

  test "a release worker joins a checkout's farm head and renders a submitted job; the image is render's",
       ctx do
    cookie = Path.join(ctx.tmp_dir, "cookie")
    {:ok, _} = Cookie.create(cookie)
    creds = ["--cookie-file", cookie, "--tls", TLS.booted_dir()]
    head = "rtrelhead_#{System.unique_integer([:positive])}"
    dir = Path.join(ctx.tmp_dir, "head")

    farm =
      open(ctx, @launcher, ["farm", "--sname", head, "--dir", dir, "--no-dashboard" | creds], [])

    {:os_pid, farm_pid} = Port.info(farm, :os_pid)

    on_exit(fn ->
      System.cmd("kill", ["-TERM", Integer.to_string(farm_pid)], stderr_to_stdout: true)
    end)

    until(farm, "ready")

    worker = hidden(ctx, [ctx.release, "worker", "--join", "#{head}@localhost" | creds])
    {:os_pid, worker_pid} = Port.info(worker, :os_pid)

    on_exit(fn ->
      System.cmd("kill", ["-TERM", Integer.to_string(worker_pid)], stderr_to_stdout: true)
    end)

    until(worker, "joined #{head}@localhost")

    size = ~w(--width 48)

    {status, out} =
      checkout(
        ctx,
        ["submit", @scene, "--out", "farm.png", "--farm", "#{head}@localhost"] ++ creds ++ size
      )

    assert status == 0, out
    {status, out} = checkout(ctx, ["render", @scene, "--out", "render.png" | size])
    assert status == 0, out

    assert File.read!(Path.join(ctx.tmp_dir, "farm.png")) ==
             File.read!(Path.join(ctx.tmp_dir, "render.png"))

    {_, 0} = System.cmd("kill", ["-TERM", Integer.to_string(worker_pid)])
    assert {143, _} = collect(worker)
    {_, 0} = System.cmd("kill", ["-TERM", Integer.to_string(farm_pid)])
    assert {143, _} = collect(farm)
  end
end
