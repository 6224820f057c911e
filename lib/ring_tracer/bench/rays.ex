defmodule RingTracer.Bench.Rays do
  @help """
  Closest-hit rays per second, in the kernel alone.

      mix ring_tracer.bench rays MESH.obj [MORE.obj ...]

  Casts closest-hit rays only: 1024 x 1024 primary rays through a 45-degree
  pinhole looking at the mesh's bounding-box centre from centre + (0.3, 0.3,
  1.1) x its diagonal, and 1,048,576 incoherent rays (fixed seed); prints
  the BVH build time, Mrays/s with 1 and 2 threads, and hit counts. It is
  the kernel's own cargo example (`native/kernel/examples/bench.rs`), with
  no BEAM in the loop.
  """
  @moduledoc @help
  @behaviour RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage, do: "rays MESH.obj [MORE.obj ...]"

  @impl RingTracer.Bench
  def run([]), do: Mix.raise("usage: mix ring_tracer.bench #{usage()}")

  def run(meshes) do
    cargo = System.find_executable("cargo") || Path.expand("~/.cargo/bin/cargo")

    args = [
      "run",
      "--release",
      "-q",
      "-p",
      "ring_tracer_kernel",
      "--example",
      "bench",
      "--",
      "--raycast"
    ]

    {_, status} =
      System.cmd(cargo, args ++ Enum.map(meshes, &Path.expand/1),
        cd: "native",
        into: IO.stream(:stdio, :line),
        stderr_to_stdout: true
      )

    if status != 0, do: Mix.raise("the ray-casting benchmark failed (exit #{status})")
  end
end
