defmodule RingTracer.Bench.Rays do
  @help """
  Rays per second in the kernel alone, next to Intel Embree's.

      mix ring_tracer.bench rays MESH.obj [MORE.obj ...] [--rounds 3] [--size 1024]
                                 [--builds 5] [--embree-isa best|sse4.2|avx|avx2|avx512]

  For each mesh (the SPD teapot tessellation is
  `../shared/scenes/meshes/spd_teapot_s12_tess.obj`): the same triangles and the
  same rays (`size` x `size` primary rays in 4 x 4 tiles, and as many
  incoherent ones, closest hit and any hit; the primary hits' shadow rays
  towards a point light, any hit) through our kernel and through
  Embree 3 (`rtcIntersect1`, `rtcIntersect16`, `rtcOccluded1/16`), one
  thread and two, alternating in each round; prints Mrays/s ranges and the
  ratios of the best rounds. Embree is timed by the project's own C harness
  (`native/embree_bench`), built when Debian's `libembree-dev` is installed;
  without it the table says so and times ours only. No BEAM in the loop.
  `--embree-isa` caps the instruction set Embree may use (by default the
  widest the CPU has: AVX-512 where there is, which ours uses only in its
  packets' leaf tests).
  First, for each mesh, both BVH builds from its triangles, `builds` times
  each, alternating: the medians of their wall and CPU times (Embree's by its
  own clock too) and both trees' SAH figures, by the definition of Embree's
  BVH statistics (docs/benchmarks.md).
  `cargo run --release -p ring_tracer_kernel --example big_mesh -- OUT.obj`
  writes a 600k-triangle mesh.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage,
    do: "rays MESH.obj [MORE.obj ...] [--rounds 3] [--size 1024] [--builds 5] [--embree-isa ISA]"

  @impl RingTracer.Bench
  def run(argv) do
    {opts, meshes, _} =
      OptionParser.parse(argv,
        strict: [rounds: :integer, size: :integer, builds: :integer, embree_isa: :string]
      )

    if meshes == [], do: Mix.raise("usage: mix ring_tracer.bench #{usage()}")
    cargo = System.find_executable("cargo") || Path.expand("~/.cargo/bin/cargo")
    flags = for {k, v} <- opts, do: ["--#{String.replace(to_string(k), "_", "-")}", to_string(v)]

    args =
      ~w(run --release -q -p ring_tracer_embree_bench --) ++
        List.flatten(flags) ++ Enum.map(meshes, &Path.expand/1)

    {_, status} =
      System.cmd(cargo, args,
        cd: "native",
        into: IO.stream(:stdio, :line),
        stderr_to_stdout: true
      )

    if status != 0, do: Mix.raise("the ray-casting benchmark failed (exit #{status})")
  end
end
