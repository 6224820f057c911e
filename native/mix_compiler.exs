defmodule Mix.Tasks.Compile.RingTracerNative do
  @shortdoc "Builds the Rust NIF with cargo and places it in priv/native"
  @moduledoc """
  A Mix compiler that builds RingTracer's native kernel.

  It runs `cargo build --release -p ring_tracer_nif` in `native/` when any file
  under `native/` (sources, `Cargo.toml`, `Cargo.lock`) is newer than the
  library in `priv/native/`, then copies the cdylib to
  `priv/native/libring_tracer_nif.so`. The old library is removed before the
  copy: overwriting a shared object that a running VM has mapped can crash it.

  Loaded by `mix.exs` and listed first in its compilers, so the library is in
  place before Elixir's compiler loads `RingTracer.Native`: `RingTracer.Settings`
  and `RingTracer.Rays` call it while they compile, to read the kernel's
  defaults and counter names. Set `RING_TRACER_SKIP_NATIVE=1` to skip the
  build; a library must then be in `priv/native/` already (without one, the
  NIF module reports it missing and those two modules do not compile).
  """
  use Mix.Task.Compiler

  @workspace "native"
  @crate "ring_tracer_nif"
  @target_name "libring_tracer_nif.so"

  @impl Mix.Task.Compiler
  def run(args) do
    {opts, _, _} = OptionParser.parse(args, switches: [force: :boolean])

    cond do
      System.get_env("RING_TRACER_SKIP_NATIVE") in ["1", "true"] ->
        {:noop, []}

      opts[:force] || stale?() ->
        build()

      true ->
        {:noop, []}
    end
  end

  @impl Mix.Task.Compiler
  def clean do
    File.rm(target())
    :ok
  end

  @doc false
  @spec target() :: Path.t()
  def target, do: Path.join([File.cwd!(), "priv", "native", @target_name])

  defp sources do
    Path.wildcard(Path.join(@workspace, "**/{*.rs,Cargo.toml,Cargo.lock}"))
    |> Enum.reject(&String.contains?(&1, "/target/"))
  end

  defp stale?, do: Mix.Utils.stale?(sources(), [target()])

  defp build do
    cargo = System.find_executable("cargo") || Path.expand("~/.cargo/bin/cargo")

    unless File.exists?(cargo) do
      Mix.raise("cargo not found: install Rust (https://rustup.rs) or put cargo on PATH")
    end

    Mix.shell().info("==> cargo build --release -p #{@crate}")

    {_, status} =
      System.cmd(cargo, ["build", "--release", "-p", @crate],
        cd: @workspace,
        into: IO.stream(:stdio, :line),
        stderr_to_stdout: true
      )

    if status == 0 do
      install()
    else
      diagnostic = %Mix.Task.Compiler.Diagnostic{
        compiler_name: "ring_tracer_native",
        file: Path.join(@workspace, "Cargo.toml"),
        message: "cargo build failed with exit status #{status}",
        position: nil,
        severity: :error
      }

      Mix.shell().error(diagnostic.message)
      {:error, [diagnostic]}
    end
  end

  defp install do
    built = Path.join([@workspace, "target", "release", @target_name])
    dest = target()
    File.mkdir_p!(Path.dirname(dest))
    # Remove first: a VM that has the old library mapped keeps its inode.
    File.rm(dest)
    File.cp!(built, dest)
    {:ok, []}
  end
end
