defmodule RingTracer.Cluster.TLS do
  @moduledoc false
  # Distribution over TLS with mutual authentication (OTP's `inet_tls_dist`).
  #
  # A node's TLS folder holds three files, made by `ringtracer tls node`:
  #
  #   * `ca.pem` — the cluster's certificate authority (its key stays with
  #     whoever runs `ringtracer tls ca`, never on the nodes);
  #   * `node.pem` — this node's certificate, signed by that CA;
  #   * `node.key` — its private key, mode 0600.
  #
  # Both sides of every connection present their certificate and check the
  # other's against `ca.pem` (`verify_peer`, `fail_if_no_peer_cert`): a node
  # without a certificate, with one from another CA, or speaking plain TCP is
  # refused before any distribution message, and so before the cookie is
  # even asked for. The cookie is still checked after the handshake.
  #
  # TLS is chosen when the VM boots (`vm_args/1`: `-proto_dist inet_tls` and
  # the certificate options, file paths only, no secret); the launcher
  # (`bin/ringtracer ... --tls DIR`) passes them, and `check_booted/1` makes
  # sure a node asked for TLS really runs it.

  alias RingTracer.Error

  @files ["ca.pem", "node.pem", "node.key"]

  @doc "The files a TLS folder must hold."
  @spec files() :: [String.t()]
  def files, do: @files

  @doc """
  The VM arguments that make a node run distribution over TLS with the
  certificates in `dir`.

      iex> args = RingTracer.Cluster.TLS.vm_args("/etc/rt")
      iex> Enum.take(args, 2)
      ["-proto_dist", "inet_tls"]
      iex> "verify_peer" in args and "/etc/rt/node.key" in args
      true
  """
  @spec vm_args(Path.t()) :: [String.t()]
  def vm_args(dir) do
    dir = Path.expand(dir)
    [ca, cert, key] = Enum.map(@files, &Path.join(dir, &1))

    side = fn s ->
      [
        "#{s}_certfile",
        cert,
        "#{s}_keyfile",
        key,
        "#{s}_cacertfile",
        ca,
        "#{s}_verify",
        "verify_peer",
        "#{s}_secure_renegotiate",
        "true",
        "#{s}_depth",
        "2"
      ]
    end

    ["-proto_dist", "inet_tls", "-ssl_dist_opt"] ++
      side.("server") ++ ["server_fail_if_no_peer_cert", "true"] ++ side.("client")
  end

  @doc """
  Whether this VM runs distribution over TLS: exactly one `-proto_dist
  inet_tls` among its boot arguments (OTP's `net_kernel` falls back to
  plain TCP when `-proto_dist` is given twice).
  """
  @spec enabled?() :: boolean()
  def enabled? do
    match?({:ok, [[~c"inet_tls"]]}, :init.get_argument(:proto_dist))
  end

  @doc "The TLS folder this VM was booted with (that of its certificate), or nil."
  @spec booted_dir() :: Path.t() | nil
  def booted_dir do
    case List.keyfind(boot_pairs(), "server_certfile", 0) do
      {_, cert} -> Path.dirname(cert)
      nil -> nil
    end
  end

  @doc """
  Checks a node's TLS folder: the three files exist, the key is readable by
  its owner only, and this VM was booted with TLS distribution.
  """
  @spec check_booted(Path.t()) :: :ok | {:error, Error.t()}
  def check_booted(dir) do
    with :ok <- check_dir(dir) do
      if enabled?(),
        do: :ok,
        else:
          {:error,
           Error.new(
             :distribution,
             "--tls is chosen when the VM starts: run this through bin/ringtracer " <>
               "(which passes the TLS flags), or start the VM with " <>
               "ELIXIR_ERL_OPTIONS=\"#{Enum.join(vm_args(dir), " ")}\""
           )}
    end
  end

  @doc """
  Checks a TLS folder: it holds the three files, every folder on the way
  to it (and every symbolic link followed) belongs to this user or to root
  and no other user can change it (or it is sticky, as `/tmp`, where
  nobody can rename what is not theirs), the folder is this user's, no other
  user can change `ca.pem` or `node.pem` (this user's or root's) or read
  `node.key` (this user's), and the node's certificate is valid now.

  The checks are made on descriptors, folder by folder from `/`
  (`ring_tracer_kernel::safe_fs::trusted_dir`): since nobody else can
  rename or replace anything on the way, the files OTP's ssl later reads
  by these paths are the files checked.
  """
  @spec check_dir(Path.t() | nil) :: :ok | {:error, Error.t()}
  def check_dir(nil),
    do: {:error, Error.new(:distribution, "this VM's TLS options name no certificate")}

  def check_dir(dir) do
    missing = Enum.reject(@files, &File.regular?(Path.join(dir, &1)))

    cond do
      not File.dir?(dir) ->
        tls_error("--tls #{dir}: no such folder (make one with: ringtracer tls node)")

      missing != [] ->
        tls_error(
          "--tls #{dir}: missing #{Enum.join(missing, ", ")} (make them with: ringtracer tls node)"
        )

      true ->
        with :ok <- trusted(dir), do: valid_now(Path.join(dir, "node.pem"))
    end
  end

  defp trusted(dir) do
    case RingTracer.Native.fs_check_trusted(dir, ["ca.pem", "node.pem"], ["node.key"]) do
      {:ok, _} -> :ok
      {:error, {nil, file, message}} -> tls_error("#{file} #{message}")
      {:error, {_posix, file, message}} -> tls_error("#{file}: #{message}")
    end
  end

  @doc """
  Checks that the certificate in `pem` is valid at this moment: one not yet
  valid and one expired are told apart (a machine's clock is often what is
  wrong).
  """
  @spec valid_now(Path.t()) :: :ok | {:error, Error.t()}
  def valid_now(pem) do
    with {:ok, text} <- File.read(pem),
         [{:Certificate, der, _} | _] <- :public_key.pem_decode(text),
         {:OTPCertificate, tbs, _, _} <- :public_key.pkix_decode_cert(der, :otp),
         {:Validity, from, until} <- elem(tbs, 5) do
      now = :calendar.datetime_to_gregorian_seconds(:calendar.universal_time())
      from_s = :pubkey_cert.time_str_2_gregorian_sec(from)
      until_s = :pubkey_cert.time_str_2_gregorian_sec(until)

      cond do
        now < from_s ->
          tls_error(
            "#{pem} is not valid yet: only from #{date(from_s)} UTC (is this machine's " <>
              "clock right? it says #{date(now)})"
          )

        now > until_s ->
          tls_error(
            "#{pem} expired on #{date(until_s)} UTC; make a new one with: ringtracer tls node"
          )

        true ->
          :ok
      end
    else
      _ -> tls_error("#{pem} holds no certificate that can be read")
    end
  end

  defp date(seconds) do
    {{y, mo, d}, {h, mi, _}} = :calendar.gregorian_seconds_to_datetime(seconds)

    :io_lib.format("~4..0B-~2..0B-~2..0B ~2..0B:~2..0B", [y, mo, d, h, mi])
    |> IO.iodata_to_binary()
  end

  defp tls_error(message), do: {:error, Error.new(:distribution, message)}

  @doc """
  Why a connection to `node` failed, as far as a TLS handshake with its
  distribution port (from epmd) tells. A TLS node offers its own
  certificates and reports what the handshake said; a plain node learns
  whether the other side speaks TLS at all.
  """
  @spec diagnose(node()) :: String.t()
  def diagnose(node) do
    with {:ok, name, host} <- split(node),
         {:port, port, _version} <- :erl_epmd.port_please(name, host, 5_000) do
      handshake(host, port, enabled?())
    else
      :noport ->
        "no node of that name runs on its host (epmd does not know it); " <>
          "start it with: ringtracer worker --sname NAME"

      {:error, why} when is_binary(why) ->
        why

      other ->
        "epmd on its host could not be asked: #{inspect(other)}"
    end
  end

  defp split(node) do
    case String.split(Atom.to_string(node), "@") do
      [name, host] -> {:ok, String.to_charlist(name), String.to_charlist(host)}
      _ -> {:error, "#{node} is not a node name (NAME@HOST)"}
    end
  end

  @cookie_hint "each node reads its cookie from --cookie-file, default ~/.erlang.cookie"

  defp handshake(host, port, true) do
    opts = [active: false, versions: [:"tlsv1.2"]] ++ client_opts()

    case ssl_connect(host, port, opts) do
      {:ok, socket} ->
        :ssl.close(socket)
        "the TLS handshake succeeds, so the cookies differ (#{@cookie_hint})"

      {:error, reason} ->
        describe(reason)
    end
  end

  defp handshake(host, port, false) do
    # Only whether it speaks TLS at all: nothing is trusted or sent.
    case ssl_connect(host, port, active: false, verify: :verify_none, log_level: :none) do
      {:ok, socket} ->
        :ssl.close(socket)
        tls_only()

      {:error, {:tls_alert, _}} ->
        tls_only()

      {:error, _} ->
        "it refused the connection: the cookies differ (#{@cookie_hint})"
    end
  end

  defp tls_only, do: "the node runs distribution over TLS only: give --tls DIR"

  defp ssl_connect(host, port, opts) do
    {:ok, _} = Application.ensure_all_started(:ssl)
    quiet_ssl()
    :ssl.connect(host, port, opts, 5_000)
  end

  @doc false
  # What a handshake says is told in one line by whoever connects
  # (RingTracer.Cluster.check/1, this module's probe); OTP's ssl would add
  # a notice of several lines on stderr for a refused one, and a warning
  # about verify_none for a probe that trusts nothing.
  @spec quiet_ssl() :: :ok
  def quiet_ssl do
    _ = Application.load(:ssl)
    _ = :logger.set_application_level(:ssl, :error)
    :ok
  end

  # This node's client options, from its boot arguments.
  defp client_opts do
    for {"client_" <> key, value} <- boot_pairs(),
        key in ["certfile", "keyfile", "cacertfile", "verify"] do
      case key do
        "verify" -> {:verify, String.to_existing_atom(value)}
        _ -> {String.to_existing_atom(key), String.to_charlist(value)}
      end
    end
  end

  # The `-ssl_dist_opt` key-value pairs this VM was booted with.
  defp boot_pairs do
    case :init.get_argument(:ssl_dist_opt) do
      {:ok, args} -> args |> Enum.concat() |> chunk_pairs()
      :error -> []
    end
  end

  defp chunk_pairs(words) do
    words
    |> Enum.map(&List.to_string/1)
    |> Enum.chunk_every(2)
    |> Enum.flat_map(fn
      [k, v] -> [{k, v}]
      _ -> []
    end)
  end

  @doc false
  @spec describe(term()) :: String.t()
  def describe({:tls_alert, {kind, detail}}), do: alert(kind, one_line(detail))
  def describe({:tls_alert, kind}) when is_atom(kind), do: alert(kind, "")

  def describe({:options, _} = reason),
    do: "this node's TLS options are wrong: #{inspect(reason)}"

  def describe(reason) when reason in [:closed, :timeout],
    do: "it did not take part in a TLS handshake: it speaks plain TCP distribution"

  def describe(reason), do: "the TLS handshake failed: #{inspect(reason)}"

  defp alert(:unknown_ca, _),
    do: "the TLS handshake failed: its certificate is not signed by our CA (unknown CA)"

  defp alert(:certificate_required, _),
    do: "the TLS handshake failed: it requires a client certificate"

  defp alert(:bad_certificate, detail),
    do: "the TLS handshake failed: a certificate was refused (#{detail})"

  defp alert(:handshake_failure, detail),
    do: "the TLS handshake failed (#{detail})"

  defp alert(:certificate_expired, _),
    do:
      "the TLS handshake failed: a certificate is outside its validity dates (expired, or " <>
        "not valid yet: check both machines' clocks and the dates of each node.pem)"

  defp alert(kind, detail), do: String.trim("the TLS handshake failed: #{kind} #{detail}")

  # OTP's alert texts end with a newline, some hold several lines.
  defp one_line(detail), do: detail |> to_string() |> String.split() |> Enum.join(" ")
end
