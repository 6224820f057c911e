defmodule RingTracer.Bench.Sequence do
  @help """
  Sequences (issue 41): a camera flight's frames through one ring
  (`RingTracer.render_sequence/2`), against the ideal, the bare kernel,
  one command per frame and POV-Ray's own animation loop.

      mix ring_tracer.bench sequence [--runs 3] [--size 512] [--atoms 2] [--flight-atoms 4]
                                     [--pov-dir DIR] [--no-commands]

  One row per target, each a time measured against another, their ratio
  and the target (`ok` or `MISSED`); times in seconds, medians of `--runs`
  runs (default 3) after one warm-up, the two sides of a row alternating
  within each run and its ratio the median of the runs' ratios:

    1. `fly-through balance`: `priv/scenes/balls_flythrough.toml` (24
       frames, only the camera moves, SPD `balls_s3`) at `--size` through
       one ring of 8 children of speeds 1 to 8 (`--flight-atoms` atoms
       each, default 4: a frame of the sequence needs fewer than one image
       alone, since a child that ends its part of a frame goes on with the
       next one; with 16, as `balance` has, the ratio was higher here), in
       this VM: the sequence's makespan (`RingTracer.Result`'s
       `:elapsed_us`) over its ideal (`:ideal_us`). Target at most 1.03.
       Beside it, `fly-through floor`: the same atoms of every frame on
       grandchildren of the same speeds, each fed the next atom from one
       shared counter, no protocol and no parent
       (`RingTracer.Bench.Balance.floor_of/3`): what slowdowns by sleeping
       leave of two cores whatever the strategy.
    2. `tetra_s6 x48`: `priv/scenes/tetra_flythrough.toml` (48 frames of
       SPD `tetra_s6`, only the camera moves) at `--size` through 2 equal
       children of `--atoms` atoms each (default 2: frames of some 12 ms,
       where each atom's kernel call and messages cost some 12 us, and
       where a child that ends its part of a frame goes on with the next
       one, so that more atoms per frame buy little balance; 2 rather than
       1 leave the last frames' strips something to hand over), from the first
       atom to the last frame's completion, against the bare kernel: each
       frame traced alone by `RingTracer.Native.render_image/3` with 2
       threads, summed. The consumer writes each frame to a PNG
       (`RingTracer.Image`) as it arrives, overlapping the tracing;
       `write_s` is the time it spent writing, not in the makespan (the
       frames are not acknowledged, `ack: false`: the writes share the
       cores but do not hold the ring back).
       Target at most 1.03. Beside it, `tetra_s6 x48 floor`: the kernel's
       frames plus their PNGs' encoding alone (`RingTracer.Native.encode_png/3`,
       its `write_s`) spread over the dirty CPU schedulers, what tracing and
       writing need of these cores; and `tetra_s6 x48 unwritten`: the same
       sequence not writing its frames, the ring's own cost, target at
       most 1.03.
    3. `separate commands`: the fly-through as 24 commands
       `bin/ringtracer render balls_flythrough.toml --frame K --width S
       --height S --out DIR/f_K.png` (the wall time of all 24) against one
       command `bin/ringtracer render balls_flythrough.toml --width S
       --height S --out DIR/f_####.png` (24 files), each command booting a
       VM of its own (`RINGTRACER_SERVER=off`). Target: the sequence at
       least 3x faster. `-` when a command fails or the sequence command
       does not write the 24 frames, with the reason under the table.
    4. `POV-Ray's animation loop`: `povray +KFI1 +KFF24 +WS +HS +WT2 -D -A`
       (the whole command) on SPD's `balls_s3.pov` (in `--pov-dir`, by
       default `../shared/scenes/spd/pov`) with its camera replaced by the
       fly-through's own camera at each frame (`pov_animation/2`), against
       row 3's sequence command: ours over POV-Ray's, target at most 0.22.
       Skipped without `povray` or the file.

  `--no-commands` leaves out rows 3 and 4 (they build and boot the
  launcher's release). From iex, `measure/1` takes the same as a keyword
  list (`commands: false`), and `:bin` and `:povray`, the executables
  to run instead of `bin/ringtracer` and the `povray` on the PATH.
  """
  @moduledoc false
  @behaviour RingTracer.Bench

  import RingTracer.Bench
  alias RingTracer.{Image, Native, Output, Scene, Settings}
  alias RingTracer.Bench.PovRay

  @flythrough "priv/scenes/balls_flythrough.toml"
  @tetra "priv/scenes/tetra_flythrough.toml"
  @pov_scene "balls_s3.pov"
  @flight_speeds Enum.to_list(1..8)
  # A sequence, the commands and POV-Ray's loop each get this long.
  @deadline_ms 30 * 60_000

  @switches [
    runs: :integer,
    size: :integer,
    atoms: :integer,
    flight_atoms: :integer,
    pov_dir: :string,
    commands: :boolean
  ]

  @typedoc """
  A row of the table: the time measured (`:measured_us`) against another
  (`:against_us`), their ratio, its target, the consumer's write time
  (row 2), a detail printed under the table, and, for a row not measured,
  why.
  """
  @type row :: %{
          required(:name) => String.t(),
          required(:measured_us) => number() | nil,
          required(:against_us) => number() | nil,
          required(:ratio) => float() | nil,
          required(:target) => {:at_most | :at_least, number()},
          required(:write_us) => number() | nil,
          required(:note) => String.t() | nil,
          optional(:detail) => String.t()
        }

  @typedoc "A camera as `RingTracer.Native.scene_camera/1` gives it."
  @type camera :: %{
          from: {float(), float(), float()},
          forward: {float(), float(), float()},
          right: {float(), float(), float()},
          up: {float(), float(), float()},
          fov: float()
        }

  @impl RingTracer.Bench
  def help, do: @help

  @impl RingTracer.Bench
  def usage,
    do:
      "sequence [--runs 3] [--size 512] [--atoms 2] [--flight-atoms 4] [--pov-dir DIR] [--no-commands]"

  @impl RingTracer.Bench
  def run(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, [], []} ->
        Mix.Task.run("app.start")
        measure(opts)

      {_, rest, invalid} ->
        bad = Enum.map(invalid, &elem(&1, 0)) ++ rest

        Mix.raise(
          "sequence: unknown option or argument #{Enum.join(bad, " ")}; usage: #{usage()}"
        )
    end
  end

  @doc """
  Runs the benchmark, prints its table and returns its rows.

  ## Options

    * `:runs` — runs per row (default 3)
    * `:size` — the frames' width and height (default 512)
    * `:atoms` — atoms per child in row 2 (default 2)
    * `:flight_atoms` — atoms per child in row 1 (default 4)
    * `:pov_dir` — the folder of the SPD `.pov` files (default
      `RingTracer.Bench.PovRay.default_dir/0`)
    * `:commands` — whether to run rows 3 and 4 (default true)
    * `:bin` — the launcher (default `bin/ringtracer`)
    * `:povray` — POV-Ray's executable (default the one on the PATH)
  """
  @spec measure(keyword()) :: [row()]
  def measure(opts \\ []) do
    {:ok, _} = Application.ensure_all_started(:ring_tracer)
    runs = opts[:runs] || 3
    size = opts[:size] || 512
    atoms = opts[:atoms] || 2
    flight_atoms = opts[:flight_atoms] || 4

    info(
      "sequences: #{size}x#{size}, median of #{runs} after a warm-up; " <>
        "times in seconds; #{vm()}; load average #{load()}"
    )

    tmp = private_tmp_dir!("ringtracer-bench-sequence")

    rows =
      try do
        flight(runs, size, flight_atoms) ++
          tetra(runs, size, atoms, tmp) ++
          commands(opts, runs, size, tmp)
      after
        File.rm_rf(tmp)
      end

    print_table(
      ~w(row measured_s against_s ratio target verdict write_s),
      Enum.map(rows, &cells/1)
    )

    info(
      "\n1: #{@flythrough}, 24 frames through 8 children (speeds 1..8) x #{flight_atoms} atoms: " <>
        "makespan against ideal; floor: the same atoms on grandchildren of the same speeds fed " <>
        "from one counter, no protocol\n" <>
        "2: #{@tetra}, 48 frames through 2 children x #{atoms} atoms: first atom to last frame, " <>
        "against the kernel's frames alone (2 threads), summed; write_s: the PNGs, written as the frames came; " <>
        "floor: the kernel's frames and their PNGs' encoding (write_s) spread over the dirty CPU schedulers; " <>
        "unwritten: the sequence not writing its frames\n" <>
        "3: whole commands, each its own VM: 24 x `render --frame K` against one `render --out f_####.png`\n" <>
        "4: povray +KFI1 +KFF24 +WT2 -D -A, balls_s3.pov with the fly-through's cameras, " <>
        "against row 3's sequence command"
    )

    Enum.each(rows, fn row ->
      if row[:detail], do: info("#{legend(row)}: #{row.detail}")
      if row.note, do: info("#{legend(row)}: #{row.note}")
    end)

    info(
      "load average at the end #{load()} (this benchmark alone makes about #{System.schedulers_online()}: more is other work)"
    )

    rows
  end

  @doc """
  A row's cells as printed.

      iex> RingTracer.Bench.Sequence.cells(%{name: "tetra_s6 x48", measured_us: 1_020_000,
      ...>   against_us: 1_000_000, ratio: 1.02, target: {:at_most, 1.03}, write_us: 120_000, note: nil})
      ["tetra_s6 x48", "1.020", "1.000", "1.020", "<= 1.03", "ok", "0.120"]
      iex> RingTracer.Bench.Sequence.cells(%{name: "separate commands", measured_us: nil,
      ...>   against_us: nil, ratio: nil, target: {:at_least, 3}, write_us: nil, note: "failed"})
      ["separate commands", nil, nil, nil, ">= 3.00", nil, nil]
  """
  @spec cells(row()) :: [String.t() | nil]
  def cells(%{target: nil} = row) do
    row
    |> Map.put(:target, {:at_most, 0})
    |> cells()
    |> List.replace_at(4, nil)
    |> List.replace_at(5, nil)
  end

  def cells(row) do
    {op, bound} = row.target

    target =
      if(op == :at_most, do: "<= ", else: ">= ") <>
        :erlang.float_to_binary(bound / 1, decimals: 2)

    verdict =
      row.ratio &&
        if(if(op == :at_most, do: row.ratio <= bound, else: row.ratio >= bound),
          do: "ok",
          else: "MISSED"
        )

    [
      row.name,
      row.measured_us && secs(row.measured_us),
      row.against_us && secs(row.against_us),
      row.ratio && fmt(row.ratio),
      target,
      verdict,
      row.write_us && secs(row.write_us)
    ]
  end

  # A row's number in the legend under the table.
  defp legend(%{name: "fly-through" <> _}), do: 1
  defp legend(%{name: "tetra_s6" <> _}), do: 2
  defp legend(%{name: "separate" <> _}), do: 3
  defp legend(_row), do: 4

  # The 1-minute load average (Linux), or "?" where there is none.
  defp load do
    case File.read("/proc/loadavg") do
      {:ok, text} -> hd(String.split(text))
      {:error, _} -> "?"
    end
  end

  # Row 1: the fly-through on 8 children of speeds 1..8, makespan over ideal.
  defp flight(runs, size, atoms) do
    job = [children: 8, speeds: @flight_speeds, atoms: atoms, width: size, height: size]
    {:ok, scene} = Scene.load(@flythrough)

    render = fn ->
      {:ok, result, _} = sequence(scene, job, nil)
      {:ok, result}
    end

    {:ok, _} = render.()
    r = median_result(runs, render)
    floor = fn -> flight_floor(scene, size, atoms) end
    f = median_result(runs, floor)

    [
      %{
        name: "fly-through balance",
        measured_us: r.elapsed_us,
        against_us: r.ideal_us,
        ratio: r.elapsed_us / max(r.ideal_us, 1),
        target: {:at_most, 1.03},
        write_us: nil,
        note: nil
      },
      %{
        name: "fly-through floor",
        measured_us: f.elapsed_us,
        against_us: f.ideal_us,
        ratio: f.elapsed_us / max(f.ideal_us, 1),
        target: nil,
        write_us: nil,
        note: nil
      }
    ]
  end

  # The same atoms of every frame, on grandchildren of the same speeds fed
  # from one counter, with no protocol and no parent
  # (`RingTracer.Bench.Balance.floor_of/3`).
  defp flight_floor(scene, size, atoms) do
    settings = %Settings{width: size, height: size}

    layout =
      size |> RingTracer.Layout.new(size, 8, atoms) |> RingTracer.Layout.with_frames(scene.frames)

    spec = %RingTracer.Job.Spec{
      id: make_ref(),
      source: scene.source,
      settings: settings,
      layout: layout,
      caller: self(),
      frames: Enum.to_list(0..(scene.frames - 1))
    }

    :ok = RingTracer.SceneCache.put(scene)
    {:ok, context} = RingTracer.Kernel.Native.prepare(spec, [])
    RingTracer.Bench.Balance.floor_of({RingTracer.Kernel.Native, context}, layout, @flight_speeds)
  end

  # Row 2: tetra's 48 frames on 2 children, from the first atom to the last
  # frame, against the bare kernel's frames alone, summed.
  defp tetra(runs, size, atoms, tmp) do
    {:ok, scene} = Scene.load(@tetra)
    native = Settings.to_native(%Settings{width: size, height: size})

    refs =
      for f <- 0..(scene.frames - 1) do
        {:ok, ref} = Native.scene_frame(scene.ref, f)
        ref
      end

    kernel = fn ->
      refs
      |> Enum.map(fn ref ->
        {us, {:ok, _}} = :timer.tc(fn -> Native.render_image(ref, native, 2) end)
        us
      end)
      |> Enum.sum()
    end

    job = [children: 2, atoms: atoms, width: size, height: size]

    ring = fn write? ->
      out = if write?, do: Path.join(tmp, "tetra")
      if out, do: :ok = Output.private_dir(out)
      {:ok, result, write_us} = sequence(scene, job, out)
      if out, do: File.rm_rf(out)

      first =
        result.children |> Enum.map(& &1.first_atom_us) |> Enum.reject(&is_nil/1) |> Enum.min()

      last = result.frames |> Enum.map(& &1.completed_us) |> Enum.max()
      {last - first, write_us}
    end

    # The CPU the frames' PNGs take, each encoded alone (no tracing
    # beside it): what writing them needs of these cores whenever it runs.
    encode = fn ->
      refs
      |> Enum.map(fn ref ->
        {:ok, {pixels, _}} = Native.render_image(ref, native, 2)
        {us, {:ok, _}} = :timer.tc(fn -> Native.encode_png(size, size, pixels) end)
        us
      end)
      |> Enum.sum()
    end

    # Each run: the kernel, the sequence writing its frames, the same not
    # writing them (what the writes cost the ring on these cores).
    runs_of = fn n -> for _ <- 1..n, do: {kernel.(), ring.(true), ring.(false)} end
    _ = runs_of.(1)
    samples = runs_of.(runs)
    kernel_us = median(Enum.map(samples, fn {k, _, _} -> k end))
    encode_us = median(for _ <- 1..runs, do: encode.())
    # The floor of tracing and writing on this machine's cores: the kernel's
    # frames plus their encoding spread over the same cores.
    floor_us = kernel_us + div(encode_us, :erlang.system_info(:dirty_cpu_schedulers_online))

    [
      %{
        name: "tetra_s6 x48",
        measured_us: median(Enum.map(samples, fn {_, {r, _}, _} -> r end)),
        against_us: kernel_us,
        ratio: median(Enum.map(samples, fn {k, {r, _}, _} -> r / k end)),
        target: {:at_most, 1.03},
        write_us: median(Enum.map(samples, fn {_, {_, w}, _} -> w end)),
        note: nil
      },
      %{
        name: "tetra_s6 x48 floor",
        measured_us: floor_us,
        against_us: kernel_us,
        ratio: floor_us / max(kernel_us, 1),
        target: nil,
        write_us: encode_us,
        note: nil
      },
      %{
        name: "tetra_s6 x48 unwritten",
        measured_us: median(Enum.map(samples, fn {_, _, {r, _}} -> r end)),
        against_us: kernel_us,
        ratio: median(Enum.map(samples, fn {k, _, {r, _}} -> r / k end)),
        target: {:at_most, 1.03},
        write_us: nil,
        note: nil
      }
    ]
  end

  @doc """
  Renders a sequence of `scene` with the options `job`
  (`RingTracer.render_sequence/2`) and consumes its frames as they come:
  with `out`, a folder, each is written there as `f_NNNN.png` (its number
  in the scene) through `RingTracer.Image`, the folder held open as the
  command line's sequences do; frames are not acknowledged (no `:ack`).
  Returns the sequence's result and the microseconds spent writing.
  """
  @spec sequence(Scene.t() | Path.t(), keyword(), Path.t() | nil) ::
          {:ok, RingTracer.Result.t(), non_neg_integer()} | {:error, RingTracer.Error.t()}
  def sequence(scene, job, out) do
    with {:ok, out} <- open(out),
         {:ok, handle} <- RingTracer.render_sequence(scene, job) do
      consume(handle, out, 0, System.monotonic_time(:millisecond) + @deadline_ms)
    end
  end

  # The output folder, held open (`RingTracer.Output.open_dir/1`) as the CLI's is.
  defp open(nil), do: {:ok, nil}

  defp open(path) do
    with {:ok, dir} <- Output.open_dir(path), do: {:ok, {path, dir}}
  end

  defp consume(%{id: id} = handle, out, write_us, deadline) do
    wait = max(deadline - System.monotonic_time(:millisecond), 0)

    receive do
      {RingTracer, ^id, {:frame, n, frame}} ->
        us = if out, do: write_frame(out, n, frame), else: 0
        consume(handle, out, write_us + us, deadline)

      {RingTracer, ^id, {:progress, _, _}} ->
        consume(handle, out, write_us, deadline)

      {RingTracer, ^id, {:ok, result}} ->
        {:ok, result, write_us}

      {RingTracer, ^id, {:error, error}} ->
        {:error, error}
    after
      wait ->
        RingTracer.cancel(handle)
        raise "the sequence did not end within #{div(@deadline_ms, 60_000)} minutes"
    end
  end

  defp write_frame({path, dir}, n, frame) do
    name = "f_" <> String.pad_leading(Integer.to_string(n), 4, "0") <> ".png"

    {us, :ok} =
      :timer.tc(fn ->
        Image.write(Path.join(path, name), frame.width, frame.height, frame.pixels, in: dir)
      end)

    us
  end

  # Rows 3 and 4: whole commands.
  defp commands(opts, runs, size, tmp) do
    separate = %{
      name: "separate commands",
      measured_us: nil,
      against_us: nil,
      ratio: nil,
      target: {:at_least, 3},
      write_us: nil,
      note: nil
    }

    pov = %{separate | name: "POV-Ray's animation loop", target: {:at_most, 0.22}}

    if Keyword.get(opts, :commands, true) do
      bin = opts[:bin] || Path.expand("bin/ringtracer")
      povray = Keyword.get_lazy(opts, :povray, &PovRay.executable/0)
      pov_file = Path.join(opts[:pov_dir] || PovRay.default_dir(), @pov_scene)
      command_rows(separate, pov, bin, povray, pov_file, runs, size, tmp)
    else
      [%{separate | note: "not run (--no-commands)"}, %{pov | note: "not run (--no-commands)"}]
    end
  end

  defp command_rows(separate, pov, bin, povray, pov_file, runs, size, tmp) do
    scene = Path.expand(@flythrough)
    {:ok, loaded} = Scene.load(scene)
    frames = loaded.frames
    size_args = ["--width", "#{size}", "--height", "#{size}"]

    # The launcher builds itself first when it is stale: not part of any run.
    warm = Path.join(tmp, "warm.png")

    case command(bin, [
           "render",
           scene,
           "--frame",
           "1",
           "--width",
           "8",
           "--height",
           "8",
           "-o",
           warm
         ]) do
      {:ok, _} ->
        pov_job = pov_job(povray, pov_file, loaded, size, tmp)

        one_run = fn ->
          dir = Path.join(tmp, "run")
          File.rm_rf(dir)
          :ok = Output.private_dir(dir)
          seq = sequence_command(bin, scene, size_args, frames, dir)

          sep =
            Enum.reduce_while(1..frames, {:ok, 0}, fn k, {:ok, total} ->
              out = Path.join(dir, "f_#{k}.png")

              case command(
                     bin,
                     ["render", scene, "--frame", "#{k}"] ++ size_args ++ ["--out", out]
                   ) do
                {:ok, us} -> {:cont, {:ok, total + us}}
                {:error, why} -> {:halt, {:error, "frame #{k}: #{why}"}}
              end
            end)

          theirs = if match?({:ok, _}, pov_job), do: pov_run(elem(pov_job, 1), dir)
          File.rm_rf(dir)
          {seq, sep, theirs}
        end

        _ = one_run.()
        samples = for _ <- 1..runs, do: one_run.()
        [separate_row(separate, samples), pov_row(pov, pov_job, samples)]

      {:error, why} ->
        note = "`#{bin} render` failed: #{why}"
        [%{separate | note: note}, %{pov | note: note}]
    end
  end

  # One command for the whole sequence: its wall time, once it wrote every frame.
  defp sequence_command(bin, scene, size_args, frames, dir) do
    out = Path.join(dir, "seq")
    :ok = Output.private_dir(out)
    args = ["render", scene] ++ size_args ++ ["--out", Path.join(out, "f_####.png")]

    with {:ok, us} <- command(bin, args) do
      written = out |> File.ls!() |> Enum.count(&String.ends_with?(&1, ".png"))

      if written == frames,
        do: {:ok, us},
        else: {:error, "the sequence command wrote #{written} images, not #{frames}"}
    end
  end

  # Row 3: the separate commands against the sequence command.
  defp separate_row(row, samples), do: pair_row(row, for({s, p, _} <- samples, do: {p, s}))

  # Row 4: the sequence command against POV-Ray's loop.
  defp pov_row(row, {:error, why}, samples),
    do: pair_row(row, for({s, _, _} <- samples, do: {s, {:error, why}}))

  defp pov_row(row, {:ok, _}, samples), do: pair_row(row, for({s, _, t} <- samples, do: {s, t}))

  # A row from each run's two sides (`{:ok, us}` or `{:error, why}`): each
  # side's median where it never failed, their ratio where neither did,
  # and the first failure's reason.
  defp pair_row(row, pairs) do
    side = fn i ->
      values = Enum.map(pairs, &elem(&1, i))
      if Enum.all?(values, &match?({:ok, _}, &1)), do: median(Enum.map(values, &elem(&1, 1)))
    end

    ratios = for {{:ok, m}, {:ok, a}} <- pairs, do: m / a
    why = Enum.find_value(pairs, fn {m, a} -> error(m) || error(a) end)

    %{
      row
      | measured_us: side.(0),
        against_us: side.(1),
        ratio: if(why == nil, do: median(ratios)),
        note: why
    }
  end

  defp error({:error, why}), do: why
  defp error(_), do: nil

  # POV-Ray's animation of the fly-through: the SPD file with our cameras, written once.
  defp pov_job(nil, _file, _scene, _size, _tmp),
    do: {:error, "povray not installed (apt-get install povray)"}

  defp pov_job(povray, file, scene, size, tmp) do
    with {:ok, text} <- read(file),
         {:ok, animated} <- pov_animation(text, cameras(scene)) do
      input = Path.join(tmp, "balls_s3_flythrough.pov")
      :ok = Output.write(input, animated)

      {:ok,
       %{
         povray: povray,
         args:
           ["+I#{input}", "+KFI1", "+KFF#{scene.frames}", "+W#{size}", "+H#{size}"] ++
             ["+WT2", "-D", "-A"]
       }}
    end
  end

  defp read(file) do
    case File.read(file) do
      {:ok, text} -> {:ok, text}
      {:error, reason} -> {:error, "#{file}: #{:file.format_error(reason)}"}
    end
  end

  defp pov_run(%{povray: povray, args: args}, dir) do
    case command(povray, args ++ ["+O#{Path.join(dir, "pov.png")}"]) do
      {:ok, us} -> {:ok, us}
      {:error, why} -> {:error, "povray: #{why}"}
    end
  end

  @doc """
  The camera of each frame of `scene` (a loaded animated scene), in order.
  """
  @spec cameras(Scene.t()) :: [camera()]
  def cameras(%Scene{} = scene) do
    for f <- 0..(scene.frames - 1) do
      {:ok, ref} = Native.scene_frame(scene.ref, f)
      Native.scene_camera(ref)
    end
  end

  @doc """
  POV-Ray's camera vectors for `camera`, as the SPD's `.pov` files write
  them: `location` the eye, `direction` the unit view direction, `right`
  and `up` the image's unit right and up vectors, each scaled to
  `2 tan(fov / 2)`.

      iex> RingTracer.Bench.Sequence.pov_camera(%{from: {0.0, 0.0, 5.0}, forward: {0.0, 0.0, -1.0},
      ...>   right: {1.0, 0.0, 0.0}, up: {0.0, 1.0, 0.0}, fov: 90.0})
      %{location: {0.0, 0.0, 5.0}, direction: {0.0, 0.0, -1.0}, right: {2.0, 0.0, 0.0}, up: {0.0, 2.0, 0.0}}
  """
  @spec pov_camera(camera()) :: %{
          location: {float(), float(), float()},
          direction: {float(), float(), float()},
          right: {float(), float(), float()},
          up: {float(), float(), float()}
        }
  def pov_camera(%{from: from, forward: forward, right: right, up: up, fov: fov}) do
    span = 2 * :math.tan(fov * :math.pi() / 360)

    scale = fn {x, y, z} ->
      {Float.round(x * span, 12), Float.round(y * span, 12), Float.round(z * span, 12)}
    end

    %{location: from, direction: forward, right: scale.(right), up: scale.(up)}
  end

  @doc """
  An SPD `.pov` file's text with its camera (the `camera { ... }` block)
  replaced by one that takes, at each frame of POV-Ray's animation loop
  (`frame_number`, from 1, as `+KFI1 +KFF<n>` gives it), the vectors of
  `cameras`' frame (`pov_camera/1`), from arrays declared before it.

      iex> cam = %{from: {0.0, 0.0, 5.0}, forward: {0.0, 0.0, -1.0}, right: {1.0, 0.0, 0.0},
      ...>   up: {0.0, 1.0, 0.0}, fov: 90.0}
      iex> {:ok, pov} = RingTracer.Bench.Sequence.pov_animation(
      ...>   "camera {\\n  location <1, 2, 3>\\n} // camera\\nsphere { 0, 1 }\\n", [cam, cam])
      iex> pov =~ "location  RT_Location[frame_number - 1]" and pov =~ "sphere { 0, 1 }"
      true
      iex> RingTracer.Bench.Sequence.pov_animation("sphere { 0, 1 }", [cam])
      {:error, "no camera { ... } block to replace"}
  """
  @spec pov_animation(String.t(), [camera()]) :: {:ok, String.t()} | {:error, String.t()}
  def pov_animation(pov, cameras) do
    block = ~r/camera\s*\{[^{}]*\}/

    if Regex.match?(block, pov) do
      vectors = Enum.map(cameras, &pov_camera/1)
      n = length(vectors)

      array = fn name, key ->
        items = Enum.map_join(vectors, ",\n", &("    " <> vector(Map.fetch!(&1, key))))
        "#declare #{name} = array[#{n}] {\n#{items}\n}\n"
      end

      camera =
        "// The camera of each frame of the animation (frame_number, from 1),\n" <>
          "// as RingTracer's scene has it (mix ring_tracer.bench sequence).\n" <>
          array.("RT_Location", :location) <>
          array.("RT_Direction", :direction) <>
          array.("RT_Right", :right) <>
          array.("RT_Up", :up) <>
          "camera {\n" <>
          "    location  RT_Location[frame_number - 1]\n" <>
          "    direction RT_Direction[frame_number - 1]\n" <>
          "    right     RT_Right[frame_number - 1]\n" <>
          "    up        RT_Up[frame_number - 1]\n" <>
          "}"

      {:ok, Regex.replace(block, pov, fn _ -> camera end, global: false)}
    else
      {:error, "no camera { ... } block to replace"}
    end
  end

  defp vector({x, y, z}), do: "<#{num(x)}, #{num(y)}, #{num(z)}>"
  defp num(x), do: :erlang.float_to_binary(x / 1, decimals: 6)

  # A command's wall time, or why it failed (its exit status and last line).
  defp command(exe, args) do
    port =
      Port.open({:spawn_executable, exe}, [
        :binary,
        :exit_status,
        :stderr_to_stdout,
        args: args,
        env: [{~c"RINGTRACER_SERVER", ~c"off"}]
      ])

    t0 = System.monotonic_time(:microsecond)
    collect(port, t0, "", System.monotonic_time(:millisecond) + @deadline_ms)
  end

  defp collect(port, t0, output, deadline) do
    wait = max(deadline - System.monotonic_time(:millisecond), 0)

    receive do
      {^port, {:data, data}} ->
        collect(port, t0, binary_part_tail(output <> data), deadline)

      {^port, {:exit_status, 0}} ->
        {:ok, System.monotonic_time(:microsecond) - t0}

      {^port, {:exit_status, status}} ->
        {:error, "exit status #{status}: #{last_line(output)}"}
    after
      wait ->
        with {:os_pid, pid} <- Port.info(port, :os_pid),
             do: System.cmd("kill", ["-KILL", Integer.to_string(pid)])

        Port.close(port)
        {:error, "no end within #{div(@deadline_ms, 60_000)} minutes"}
    end
  end

  # The output's last 4 KB: what a failure's last line needs.
  defp binary_part_tail(text) when byte_size(text) > 4096,
    do: binary_part(text, byte_size(text) - 4096, 4096)

  defp binary_part_tail(text), do: text

  defp last_line(output) do
    output |> String.split("\n", trim: true) |> List.last("(no output)") |> String.trim()
  end
end
