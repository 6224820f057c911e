# Our own Mix compiler for the Rust NIF (no hex, no rustler mix package). It
# lives beside the crates and is loaded here so it can run before Elixir's
# compiler: the NIF library exists by the time modules are loaded.
unless Code.ensure_loaded?(Mix.Tasks.Compile.RingTracerNative) do
  Code.require_file("native/mix_compiler.exs", __DIR__)
end

defmodule RingTracer.MixProject do
  use Mix.Project

  def project do
    [
      app: :ring_tracer,
      version: "0.1.0",
      elixir: "~> 1.14",
      start_permanent: Mix.env() == :prod,
      compilers: [:ring_tracer_native | Mix.compilers()],
      deps: [],
      elixirc_paths: elixirc_paths(Mix.env()),
      test_coverage: [summary: [threshold: 0]],
      dialyzer_ignore: [],
      # :inets (the preview's HTTP server) is started by RingTracer.Preview, like
      # :ssl by TLS (and :public_key, which :ssl needs, for a certificate's dates), and
      # :mnesia by a farm's head (RingTracer.Farm.Store), only when used.
      xref: [
        exclude: [
          :ssl,
          :public_key,
          :pubkey_cert,
          :inets,
          :httpd,
          :httpd_util,
          :httpd_response,
          :httpd_connection_sup,
          :httpc,
          :mnesia
        ]
      ],
      aliases: aliases(),
      releases: releases()
    ]
  end

  def application do
    [
      # Debian's erlang-jiffy writes --stats JSON; PropEr and xmerl serve the tests.
      # :ssl is not started with the application (a tenth of a second of every
      # command's start-up): TLS distribution starts it at boot, and
      # RingTracer.Cluster.TLS starts it before its own handshakes.
      extra_applications: [:logger, :crypto, :jiffy] ++ test_applications(Mix.env()),
      mod: {RingTracer.Application, []}
    ]
  end

  defp test_applications(:test), do: [:proper, :xmerl]
  defp test_applications(_), do: []

  # tools/: the benchmarks, the chaos soak and their Mix tasks, run from Mix
  # in dev or test; the launcher's build and the release are lib/ alone.
  defp elixirc_paths(:test), do: ["lib", "tools/lib", "test/support"]
  defp elixirc_paths(:dev), do: ["lib", "tools/lib"]
  defp elixirc_paths(_), do: ["lib"]

  # `bin/ringtracer release` (docs/deploy.md): ERTS and every application a
  # command may start at run time, so that the release runs where neither
  # Erlang nor Elixir is installed. Its launcher (rel/overlays/bin/ringtracer)
  # boots start_clean and starts the applications itself, as the checkout's
  # does: those below are loaded on demand (TLS distribution, the preview and
  # dashboard's HTTP server, a farm's store, the certificates' dates).
  defp releases do
    [
      ring_tracer: [
        include_erts: true,
        include_executables_for: [],
        applications: [
          ring_tracer: :permanent,
          asn1: :load,
          public_key: :load,
          ssl: :load,
          inets: :load,
          mnesia: :load
        ],
        steps: [:assemble, &add_client/1]
      ]
    ]
  end

  # The thin client of `ringtracer serve` (built by `bin/ringtracer setup`),
  # beside the launcher's shared part (rel/overlays/libexec).
  defp add_client(release) do
    client = Path.join(__DIR__, "native/target/release/ringtracer-client")

    unless File.exists?(client) do
      Mix.raise("#{client} not found: build it first (bin/ringtracer setup)")
    end

    File.cp!(client, Path.join([release.path, "libexec", "ringtracer-client"]))
    release
  end

  defp aliases do
    []
  end
end
