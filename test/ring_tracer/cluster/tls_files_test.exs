defmodule RingTracer.Cluster.TLSFilesTest do
  # The launcher's TLS side (bin/ringtracer tls ..., the user's own
  # certificates) and the checks of a TLS folder: no VM is distributed.
  use ExUnit.Case, async: true

  @moduletag :tmp_dir

  import Bitwise
  alias RingTracer.Cluster.TLS

  @launcher Path.expand("bin/ringtracer")

  defp launcher(args, env \\ []),
    do: System.cmd(@launcher, args, stderr_to_stdout: true, env: env)

  defp mode(path), do: File.stat!(path).mode &&& 0o777

  test "the launcher's TLS flags are TLS.vm_args/1's, one argument each, spaces and all", %{
    tmp_dir: dir
  } do
    folder = Path.join(dir, "my certs")
    {out, 0} = launcher(["tls", "args", folder])
    assert String.split(out, <<0>>, trim: true) == TLS.vm_args(folder)
  end

  test "tls ca and tls node make private folders, and say what is wrong", %{tmp_dir: dir} do
    ca = Path.join(dir, "ca")
    {_, 0} = launcher(["tls", "ca", ca])
    assert mode(ca) == 0o700
    assert mode(Path.join(ca, "ca.key")) == 0o600

    {out, status} = launcher(["tls", "node", ca, Path.join(dir, "n1"), "bad host"])
    assert status == 2
    assert out =~ "not a host name or an IP address: 'bad host'"
    refute File.exists?(Path.join(dir, "n1"))

    open = Path.join(dir, "open")
    File.mkdir!(open)
    File.chmod!(open, 0o755)
    {out, status} = launcher(["tls", "node", ca, open, "w1.example"])
    assert status == 1
    assert out =~ "#{open} must be a folder of yours that only you can enter"
    assert File.ls!(open) == []

    n1 = Path.join(dir, "n1")
    {_, 0} = launcher(["tls", "node", ca, n1, "w1.example", "10.0.0.5"])
    assert mode(n1) == 0o700
    assert mode(Path.join(n1, "node.key")) == 0o600
    assert TLS.check_dir(n1) == :ok

    {out, status} = launcher(["tls", "node", Path.join(dir, "no_ca"), Path.join(dir, "n2")])
    assert status == 1
    assert out =~ "ca.pem not found"
  end

  test "your own certificates, made on first use: private, and the CA's key thrown away", %{
    tmp_dir: dir
  } do
    # A worker whose --ports is wrong: the launcher makes the folder, the VM refuses.
    {out, status} =
      launcher(["worker", "--sname", "rtdist_own", "--ports", "bad"], [
        {"XDG_CONFIG_HOME", dir}
      ])

    assert status == 1, out
    assert out =~ "made your own TLS certificates in #{dir}/ringtracer/tls"
    own = Path.join([dir, "ringtracer", "tls"])
    assert mode(own) == 0o700
    assert Enum.sort(File.ls!(own)) == ["ca.pem", "node.key", "node.pem"]
    assert mode(Path.join(own, "node.key")) == 0o600
    assert TLS.check_dir(own) == :ok
    {_, 0} = System.cmd("openssl", ["verify", "-CAfile", "#{own}/ca.pem", "#{own}/node.pem"])
    assert File.ls!(Path.join(dir, "ringtracer")) == ["tls"]

    # A folder that others can write is not used for a key.
    other = Path.join(dir, "other")
    File.mkdir_p!(Path.join(other, "ringtracer"))
    File.chmod!(Path.join(other, "ringtracer"), 0o777)

    {out, status} = launcher(["worker", "--sname", "rtdist_own2"], [{"XDG_CONFIG_HOME", other}])

    assert status == 1
    assert out =~ "#{other}/ringtracer must be yours and writable by you only"
    assert File.ls!(Path.join(other, "ringtracer")) == []
  end

  test "a TLS folder others can change, or a key they can read, is refused", %{tmp_dir: dir} do
    ca = Path.join(dir, "ca")
    n = Path.join(dir, "n")
    {_, 0} = launcher(["tls", "ca", ca])
    {_, 0} = launcher(["tls", "node", ca, n, "localhost"])
    File.chmod!(n, 0o777)
    assert {:error, %{message: message}} = TLS.check_dir(n)
    assert message == "#{n} can be changed by other users; fix it with: chmod 700 #{n}"
    File.chmod!(n, 0o700)
    File.chmod!(Path.join(n, "node.key"), 0o640)
    assert {:error, %{message: message}} = TLS.check_dir(n)
    assert message =~ "node.key can be read by other users; fix it with: chmod 600"
  end

  test "a TLS folder is refused when a folder on the way, or a file in it, is not closed", %{
    tmp_dir: dir
  } do
    ca = Path.join(dir, "ca")
    shared = Path.join(dir, "shared")
    File.mkdir!(shared)
    n = Path.join(shared, "n")
    {_, 0} = launcher(["tls", "ca", ca])
    {_, 0} = launcher(["tls", "node", ca, n, "localhost"])
    assert TLS.check_dir(n) == :ok
    # whoever can change a folder on the way could swap the certificates ssl reads later
    File.chmod!(shared, 0o777)
    assert {:error, %{message: message}} = TLS.check_dir(n)

    assert message ==
             "#{shared} is on the way to #{n} and can be changed by other users (mode 0777), " <>
               "who could swap what is in it; use a folder that only you and root can change"

    File.chmod!(shared, 0o755)
    # a link of this user's is followed, and checked on the far side too
    File.ln_s!(n, Path.join(dir, "via"))
    assert TLS.check_dir(Path.join(dir, "via")) == :ok
    # the certificate itself must be the file, not a link to one
    File.rename!(Path.join(n, "node.pem"), Path.join(dir, "node.pem"))
    File.ln_s!(Path.join(dir, "node.pem"), Path.join(n, "node.pem"))
    assert {:error, %{message: message}} = TLS.check_dir(n)
    assert message =~ "node.pem is a symbolic link, not a regular file"
    File.rm!(Path.join(n, "node.pem"))
    File.cp!(Path.join(dir, "node.pem"), Path.join(n, "node.pem"))
    File.chmod!(Path.join(n, "node.pem"), 0o666)
    assert {:error, %{message: message}} = TLS.check_dir(n)
    assert message =~ "node.pem can be changed by other users; fix it with: chmod go-w"
  end

  test "a certificate not valid yet is told apart from an expired one", %{tmp_dir: dir} do
    conf = Path.join(dir, "conf")

    File.write!(
      conf,
      "[ca]\ndefault_ca=d\n[d]\ndatabase=#{dir}/index\nnew_certs_dir=#{dir}\n" <>
        "serial=#{dir}/serial\ndefault_md=sha256\npolicy=p\n[p]\ncommonName=supplied\n"
    )

    {_, 0} =
      System.cmd(
        "openssl",
        ~w(req -new -nodes -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -subj /CN=x) ++
          ["-keyout", "#{dir}/k", "-out", "#{dir}/r.csr"],
        stderr_to_stdout: true
      )

    cert = fn name, from, until ->
      File.write!("#{dir}/index", "")
      File.write!("#{dir}/serial", "01\n")

      {_, 0} =
        System.cmd(
          "openssl",
          ~w(ca -batch -selfsign -notext -config) ++
            [conf, "-keyfile", "#{dir}/k", "-in", "#{dir}/r.csr", "-out", "#{dir}/#{name}"] ++
            ["-startdate", from, "-enddate", until],
          stderr_to_stdout: true
        )

      Path.join(dir, name)
    end

    future = cert.("future.pem", "400101000000Z", "410101000000Z")
    past = cert.("past.pem", "200101000000Z", "210101000000Z")
    now = cert.("now.pem", "200101000000Z", "491231000000Z")

    assert {:error, %{message: message}} = TLS.valid_now(future)
    assert message =~ "#{future} is not valid yet: only from 2040-01-01 00:00 UTC"
    assert message =~ "clock"
    assert {:error, %{message: message}} = TLS.valid_now(past)
    assert message =~ "#{past} expired on 2021-01-01 00:00 UTC"
    assert TLS.valid_now(now) == :ok
  end

  test "TLS alerts are named in one line, and not-yet-valid is not called expired" do
    message =
      TLS.describe(
        {:tls_alert,
         {:certificate_expired, ~c"received SERVER ALERT: Fatal -\n Certificate Expired\n"}}
      )

    assert message =~ "expired, or not valid yet"
    refute message =~ "\n"

    message = TLS.describe({:tls_alert, {:decrypt_error, ~c"a\nb\n"}})
    assert message == "the TLS handshake failed: decrypt_error a b"
  end
end
