defmodule RingTracer.Bench.SequenceTest do
  # not async: the sequences take both dirty schedulers
  use ExUnit.Case, async: false
  doctest RingTracer.Bench.Sequence

  import ExUnit.CaptureIO

  alias RingTracer.Bench.Sequence
  alias RingTracer.{Scene, TestScenes}

  @moduletag timeout: 300_000

  # The camera block of the SPD's balls_s3.pov (../shared/scenes/spd/pov), as it is there.
  @spd_camera """
  camera {
      location <2.1, 1.3, 1.7>
      direction <-0.700389, -0.433574, -0.566982>
      right     <-0.436046, 0.704383, -0>
      up        <-0.399372, -0.24723, 0.682401>
  } // camera
  """

  setup do
    dir = Path.join(System.tmp_dir!(), "ring_tracer_seq_#{System.unique_integer([:positive])}")
    File.mkdir_p!(dir)
    on_exit(fn -> File.rm_rf(dir) end)
    %{dir: dir}
  end

  # A launcher that does what `bin/ringtracer render` does to the files: one
  # image per --frame command, and one per frame for an --out with ####
  # (or, `sequence: false`, an exit status 2 for it, as a CLI without
  # sequences would give).
  defp launcher(dir, sequence?) do
    on_pattern =
      if sequence?,
        do:
          ~S[for i in $(seq 1 24); do : > "$(echo "$out" | sed "s/####/$(printf %04d $i)/")"; done],
        else: ~S[echo "render: unknown pattern in --out" >&2; exit 2]

    script(dir, "ringtracer", """
    out=""
    while [ $# -gt 0 ]; do
      case "$1" in --out|-o) out="$2"; shift ;; esac
      shift
    done
    case "$out" in
      *'####'*) #{on_pattern} ;;
      *) : > "$out" ;;
    esac
    """)
  end

  # A povray that keeps the file it was given (as seen.pov beside itself).
  defp povray(dir) do
    script(dir, "povray", """
    for a in "$@"; do
      case "$a" in +I*) cp "${a#+I}" "#{dir}/seen.pov" ;; esac
    done
    """)
  end

  defp script(dir, name, body) do
    path = Path.join(dir, name)
    File.write!(path, "#!/bin/sh\n" <> body)
    File.chmod!(path, 0o755)
    path
  end

  defp measure(dir, sequence?) do
    pov_dir = Path.join(dir, "pov")
    File.mkdir_p!(pov_dir)
    File.write!(Path.join(pov_dir, "balls_s3.pov"), @spd_camera <> "sphere { <0, 0, 0>, 1 }\n")

    capture_io(fn ->
      rows =
        Sequence.measure(
          runs: 1,
          size: 16,
          atoms: 2,
          flight_atoms: 2,
          bin: launcher(dir, sequence?),
          povray: povray(dir),
          pov_dir: pov_dir
        )

      send(self(), {:rows, rows})
    end)
  end

  test "prints the four rows, each measured against another with its ratio and target", %{
    dir: dir
  } do
    out = measure(dir, true)
    assert_received {:rows, rows}

    assert Enum.map(rows, & &1.name) ==
             [
               "fly-through balance",
               "fly-through floor",
               "tetra_s6 x48",
               "tetra_s6 x48 floor",
               "tetra_s6 x48 unwritten",
               "separate commands",
               "POV-Ray's animation loop"
             ]

    for row <- rows do
      assert row.note == nil
      assert row.measured_us > 0 and row.against_us > 0
      assert_in_delta row.ratio, row.measured_us / row.against_us, 1.0e-9
    end

    assert Enum.map(rows, & &1.target) ==
             [
               {:at_most, 1.03},
               nil,
               {:at_most, 1.03},
               nil,
               {:at_most, 1.03},
               {:at_least, 3},
               {:at_most, 0.22}
             ]

    # only the tetra row writes its frames, apart from its makespan; its
    # floor adds the frames' encoding, spread over the cores, to the kernel
    assert [nil, nil, write_us, encode_us, nil, nil, nil] = Enum.map(rows, & &1.write_us)
    assert write_us > 0 and encode_us > 0
    floor = Enum.at(rows, 3)
    assert floor.measured_us > floor.against_us

    [title, header | lines] = String.split(out, "\n")
    assert title =~ "sequences: 16x16, median of 1"
    assert header =~ ~r/^\s+row\s+measured_s\s+against_s\s+ratio\s+target\s+verdict\s+write_s$/

    assert Enum.at(lines, 0) =~
             ~r/fly-through balance\s+\d+\.\d{3}\s+\d+\.\d{3}\s+\d+\.\d{3}\s+<= 1.03\s+(ok|MISSED)\s+-$/

    assert Enum.at(lines, 1) =~ ~r/fly-through floor(\s+\d+\.\d{3}){3}\s+-\s+-\s+-$/

    assert Enum.at(lines, 2) =~
             ~r/tetra_s6 x48(\s+\d+\.\d{3}){3}\s+<= 1.03\s+(ok|MISSED)\s+\d+\.\d{3}$/

    assert Enum.at(lines, 3) =~ ~r/tetra_s6 x48 floor(\s+\d+\.\d{3}){3}\s+-\s+-\s+\d+\.\d{3}$/

    assert Enum.at(lines, 4) =~
             ~r/tetra_s6 x48 unwritten(\s+\d+\.\d{3}){3}\s+<= 1.03\s+(ok|MISSED)\s+-$/

    assert Enum.at(lines, 5) =~
             ~r/separate commands(\s+\d+\.\d{3}){3}\s+>= 3.00\s+(ok|MISSED)\s+-$/

    assert Enum.at(lines, 6) =~
             ~r/POV-Ray's animation loop(\s+\d+\.\d{3}){3}\s+<= 0.22\s+(ok|MISSED)\s+-$/

    # POV-Ray was given the SPD file with one camera per frame in place of its own
    seen = File.read!(Path.join(dir, "seen.pov"))
    refute seen =~ "location <2.1, 1.3, 1.7>"
    assert seen =~ "#declare RT_Location = array[24] {"
    assert seen =~ "location  RT_Location[frame_number - 1]"
    assert seen =~ "sphere { <0, 0, 0>, 1 }"
  end

  test "a sequence command that fails leaves its rows out, saying why", %{dir: dir} do
    out = measure(dir, false)
    assert_received {:rows, [flight, _, tetra, _, _, separate, pov]}
    assert flight.ratio > 0 and tetra.ratio > 0

    for row <- [separate, pov] do
      assert row.ratio == nil
      assert row.note =~ "exit status 2: render: unknown pattern in --out"
    end

    # each side's time where it did not fail: the 24 commands, POV-Ray's loop
    assert separate.measured_us > 0 and separate.against_us == nil
    assert pov.measured_us == nil and pov.against_us > 0
    assert out =~ ~r/separate commands\s+\d+\.\d{3}\s+-\s+-\s+>= 3.00\s+-\s+-/
    assert out =~ ~r/POV-Ray's animation loop\s+-\s+\d+\.\d{3}\s+-\s+<= 0.22\s+-\s+-/
    assert out =~ "3: exit status 2: render: unknown pattern in --out"
  end

  test "the fly-through's first camera, as POV-Ray takes it, is the SPD file's own" do
    [first | _] =
      cameras = Sequence.cameras(Scene.load!(TestScenes.path("balls_flythrough.toml")))

    assert length(cameras) == 24
    pov = Sequence.pov_camera(first)

    for {key, want} <- [
          location: {2.1, 1.3, 1.7},
          direction: {-0.700389, -0.433574, -0.566982},
          right: {-0.436046, 0.704383, 0.0},
          up: {-0.399372, -0.24723, 0.682401}
        ] do
      {a, b, c} = Map.fetch!(pov, key)
      {x, y, z} = want

      assert abs(a - x) + abs(b - y) + abs(c - z) < 1.0e-5,
             "#{key}: #{inspect(Map.fetch!(pov, key))}"
    end

    {:ok, text} = Sequence.pov_animation(@spd_camera, cameras)
    # each frame's vectors, in order: the first is the file's own
    assert text =~ "#declare RT_Location = array[24] {\n    <2.100000, 1.300000, 1.700000>,"
    refute text =~ "location <2.1, 1.3, 1.7>"
  end
end
