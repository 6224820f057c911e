defmodule RingTracer.Output do
  @moduledoc false
  # The files a render writes: checked before any tracing, written atomically.
  #
  # `check/2` runs before a job starts and refuses, with the option and the
  # path in the message:
  #
  #   * an extension the output's kind does not have (an image is `.png` or
  #     `.exr`, statistics `.json` or `.csv`, a timeline `.svg`, an ownership
  #     map `.png`);
  #   * a folder that does not exist or cannot be written;
  #   * an existing path that is not a regular file (a folder, a FIFO, ...);
  #   * two outputs that are the same file (also through a symlink or a hard
  #     link);
  #   * an output that is one of the render's inputs: the scene or a file it
  #     references.
  #
  # `write/2` writes to a temporary file in the same folder and renames it
  # over the target, so a failed, cancelled or interrupted render leaves any
  # earlier file untouched and never a partial one.
  #
  # Another local user may be racing every step (a folder she can write,
  # swapped for a symbolic link in between): the folder is opened once, and
  # the temporary file is made in it through that descriptor with
  # `O_CREAT | O_EXCL | O_NOFOLLOW` and mode 0600, given its final mode with
  # `fchmod` on its own descriptor, then renamed over the target in the same
  # folder (`ring_tracer_kernel::safe_fs`). No name is chmodded, nothing is
  # resolved twice. The folder is reached following only this user's or
  # root's symbolic links: a path through another user's link is refused
  # (she could point it, at any moment, at a folder of her choice).

  alias RingTracer.{Error, Native}

  @typedoc "A folder held open by the file NIFs (`write_all/1` gives it to its writes)."
  @opaque dir :: reference()

  @typedoc "What an output is: it decides the allowed extensions and the option named in errors."
  @type kind :: :image | :stats | :timeline | :ownership

  @extensions %{
    image: [".png", ".exr"],
    stats: [".json", ".csv"],
    timeline: [".svg"],
    ownership: [".png"]
  }

  @option %{image: "--out", stats: "--stats", timeline: "--timeline", ownership: "--ownership"}

  @doc "The extensions an output of `kind` may have."
  @spec extensions(kind()) :: [String.t()]
  def extensions(kind), do: Map.fetch!(@extensions, kind)

  @doc """
  Checks `outputs` (`[{kind, path}]`) against each other and against
  `inputs` (paths the render reads). Returns `:ok` or the first problem.

      iex> dir = Path.join(System.tmp_dir!(), "rt_output_doc_#{Base.url_encode64(:crypto.strong_rand_bytes(9))}")
      iex> File.mkdir_p!(dir)
      iex> scene = Path.join(dir, "scene.nff")
      iex> File.write!(scene, "v\\n")
      iex> RingTracer.Output.check([image: Path.join(dir, "a.png"), stats: Path.join(dir, "a.json")], [scene])
      :ok
      iex> {:error, error} = RingTracer.Output.check([timeline: scene], [scene])
      iex> error.message =~ "--timeline"
      true
      iex> :ok = RingTracer.Output.write(Path.join(dir, "a.json"), "{}")
      iex> File.read!(Path.join(dir, "a.json"))
      "{}"
  """
  @spec check([{kind(), Path.t()}], [Path.t()]) :: :ok | {:error, Error.t()}
  def check(outputs, inputs) do
    inputs = Enum.map(inputs, &{&1, identity(&1)})

    outputs
    |> Enum.reduce_while([], fn {kind, path}, seen ->
      with :ok <- extension(kind, path),
           :ok <- target(kind, path),
           :ok <- folder(kind, path),
           id = identity(path),
           :ok <- distinct(kind, path, id, seen),
           :ok <- not_input(kind, path, id, inputs) do
        {:cont, [{kind, path, id} | seen]}
      else
        {:error, _} = error -> {:halt, error}
      end
    end)
    |> case do
      {:error, _} = error -> error
      _ -> :ok
    end
  end

  @doc """
  Only the last of `check/2`'s rules: none of `outputs` is one of `inputs`.
  For inputs known later (the files a scene references, once it is read)
  than the outputs were checked.
  """
  @spec check_inputs([{kind(), Path.t()}], [Path.t()]) :: :ok | {:error, Error.t()}
  def check_inputs(outputs, inputs) do
    inputs = Enum.map(inputs, &{&1, identity(&1)})

    first_error(outputs, fn {kind, path} -> not_input(kind, path, identity(path), inputs) end)
  end

  # `check.(item)` of each item until one is not `:ok`: that one, else `:ok`.
  defp first_error(items, check) do
    Enum.find_value(items, :ok, fn item ->
      case check.(item) do
        :ok -> nil
        error -> error
      end
    end)
  end

  @doc """
  Writes `data` to `path` atomically: into a new file made (mode 0600,
  `O_EXCL | O_NOFOLLOW`) in the folder of `path` opened once, given its
  final permissions on its descriptor, then renamed over `path`. A file of
  this user's replaced keeps its permission bits, but never setuid, setgid
  or sticky; a file of another user's lends none (a new file's mode is used:
  she chose hers); a symbolic link at `path` is replaced, never followed.

  ## Options

    * `:mode` — the permissions of a new file (default: `0o666` less the
      umask)
    * `:in` — the folder of `path` already held open (the handle
      `write_all/1` gives its writes): the file is written there, under
      `path`'s name, without opening its folder again
  """
  @spec write(Path.t(), iodata(), keyword()) :: :ok | {:error, Error.t()}
  def write(path, data, opts \\ []) do
    result =
      case opts[:in] do
        nil ->
          put(path, data, opts[:mode], true)

        dir ->
          binary = IO.iodata_to_binary(data)
          fs(Native.fs_write_in(dir, Path.basename(path), binary, opts[:mode] || -1, true))
      end

    case result do
      {:error, reason} -> {:error, file_error(path, reason)}
      _ -> :ok
    end
  end

  @doc """
  Puts `data` at `path` as `write/3` does (`mode` that of a new file, `nil`
  the umask's), replacing what is there when `replace?`, else refusing an
  existing name with `{:error, :eexist}` and replacing nothing, ever.
  Errors are the system's reason, or words where there is none.
  """
  @spec put(Path.t(), iodata(), non_neg_integer() | nil, boolean()) ::
          :ok | {:error, File.posix() | String.t()}
  def put(path, data, mode, replace?) do
    with {:ok, _} <-
           fs(Native.fs_write(Path.expand(path), IO.iodata_to_binary(data), mode || -1, replace?)),
         do: :ok
  end

  @doc """
  Makes the folder `dir`, which must not exist yet (so it is this caller's
  own, not one someone made there first), with mode 0700 in the one
  `mkdir`, and checks the folder then opened (without following a symbolic
  link): this user's, closed to others.
  """
  @spec private_dir(Path.t()) :: :ok | {:error, File.posix() | String.t()}
  def private_dir(dir) do
    with {:ok, _dir} <- fs(Native.fs_private_dir(Path.expand(dir), false)), do: :ok
  end

  # The file NIFs' errors (`{posix, message}`, `posix` nil where the system
  # gave no reason) as the system's reason, or the words where there is none.
  defp fs({:error, {nil, message}}), do: {:error, message}
  defp fs({:error, {posix, _message}}), do: {:error, posix}
  defp fs(ok), do: ok

  # An error of the file NIFs' (`fs/1`) about `path`.
  defp file_error(path, reason) when is_atom(reason), do: Error.file(:file, path, reason)
  defp file_error(path, message), do: Error.new(:file, "#{path}: #{message}")

  @doc """
  Writes several outputs as one: runs each `{path, write}` in turn, where
  `write` writes `path` (atomically, as `write/2` and
  `RingTracer.Image.write/2` do) and returns `:ok` or an error. When one
  fails, exactly what was at each path before is put back (a file, a
  symbolic link as itself; a new one removed) and its error is returned: a
  failed render never leaves its outputs half old, half new. What is at
  each target is kept as a hidden hard link beside it (made without
  following a link, in the folder opened once) while the set is written,
  so putting it back copies nothing; no hidden file is left either way.
  A `write` of one argument is given that folder, held open (`:in` of
  `write/3` and `RingTracer.Image.write/5`), so that it writes in the very
  folder where what it replaces was kept.
  A render killed mid-way (`SIGKILL`) can leave one: the next write of
  that output removes this user's hidden links for it that are over an
  hour old (`ring_tracer_kernel::safe_fs::Dir::sweep_kept`), never another
  user's, never a name that only looks like one.

      iex> dir = Path.join(System.tmp_dir!(), "rt_write_all_doc_#{System.unique_integer([:positive])}")
      iex> File.mkdir_p!(dir)
      iex> [a, b] = [Path.join(dir, "a.json"), Path.join(dir, "b.svg")]
      iex> File.write!(a, "old")
      iex> failing = {:error, RingTracer.Error.new(:file, "b.svg: no space left on device")}
      iex> {:error, _} = RingTracer.Output.write_all([{a, fn -> RingTracer.Output.write(a, "new") end}, {b, fn -> failing end}])
      iex> {File.read!(a), File.ls!(dir)}
      {"old", ["a.json"]}
      iex> :ok = RingTracer.Output.write_all([{a, fn -> RingTracer.Output.write(a, "new") end}])
      iex> {File.read!(a), File.ls!(dir)}
      {"new", ["a.json"]}
      iex> File.rm_rf!(dir) |> length()
      2
  """
  @spec write_all([{Path.t(), (() -> result) | (dir() -> result)}]) :: :ok | {:error, Error.t()}
        when result: :ok | {:error, Error.t()}
  def write_all(writes) do
    result =
      Enum.reduce_while(writes, {:ok, []}, fn {path, write}, {:ok, done} ->
        case keep(path) do
          {:ok, {dir, _, _} = kept} ->
            case if(is_function(write, 1), do: write.(dir), else: write.()) do
              :ok -> {:cont, {:ok, [kept | done]}}
              {:error, _} = error -> {:halt, {error, [kept | done]}}
            end

          {:error, _} = error ->
            {:halt, {error, done}}
        end
      end)

    case result do
      {:ok, done} ->
        for {dir, _name, link} <- done, do: Native.fs_discard(dir, link)
        :ok

      {error, done} ->
        # the last written first, so that two writes to one name end as it began
        for {dir, name, link} <- done, do: Native.fs_put_back(dir, name, link)
        error
    end
  end

  # What is at `path` now (anything, a symbolic link as itself), as a
  # hidden hard link in its folder held open, or nil when nothing is there.
  defp keep(path) do
    full = Path.expand(path)

    with {:ok, dir} <- fs(Native.fs_open_dir(Path.dirname(full))),
         {:ok, link} <- fs(Native.fs_keep(dir, Path.basename(full))) do
      {:ok, {dir, Path.basename(full), link}}
    else
      {:error, reason} -> {:error, file_error(path, reason)}
    end
  end

  @doc """
  Only the rule of `check/2` about what is already there, for many paths
  of one `kind` (the frames of a sequence): an existing path must be a
  regular file (through symbolic links); a new name is fine. Returns `:ok`
  or the first problem.
  """
  @spec check_targets(kind(), [Path.t()]) :: :ok | {:error, Error.t()}
  def check_targets(kind, paths) do
    first_error(paths, &target(kind, &1))
  end

  @doc """
  Opens the folder `path` once, reached as `write/3` reaches it, for
  `complete?/2` and the `:in` option of `write/3` and
  `RingTracer.Image.write/5`: every file written or looked at through it is
  in that very folder, whatever is swapped on the way meanwhile.
  """
  @spec open_dir(Path.t()) :: {:ok, dir()} | {:error, Error.t()}
  def open_dir(path) do
    case fs(Native.fs_open_dir(Path.expand(path))) do
      {:ok, dir} -> {:ok, dir}
      {:error, reason} -> {:error, file_error(path, reason)}
    end
  end

  @doc """
  Whether `name` in the folder `dir` (from `open_dir/1`) is a complete
  output: a regular, non-empty file, not followed if it is a symbolic link.
  Outputs are written atomically, so a file at an output's final name is
  a whole one.

      iex> dir = Path.join(System.tmp_dir!(), "rt_complete_doc_#{System.unique_integer([:positive])}")
      iex> File.mkdir_p!(dir)
      iex> :ok = RingTracer.Output.write(Path.join(dir, "f_1.png"), "x")
      iex> File.touch!(Path.join(dir, "f_2.png"))
      iex> File.ln_s!(Path.join(dir, "f_1.png"), Path.join(dir, "f_3.png"))
      iex> {:ok, held} = RingTracer.Output.open_dir(dir)
      iex> Enum.map(~w(f_1.png f_2.png f_3.png f_4.png), &RingTracer.Output.complete?(held, &1))
      [true, false, false, false]
      iex> File.rm_rf!(dir) |> length()
      4
  """
  @spec complete?(dir(), String.t()) :: boolean()
  def complete?(dir, name) do
    Path.basename(name) == name and regular_nonempty?(dir, name)
  end

  defp regular_nonempty?(dir, name) do
    # the folder held open, named through /proc: the name is looked up in it, unfollowed
    case File.lstat(Path.join(Native.fs_dir_path(dir), name)) do
      {:ok, %File.Stat{type: :regular, size: size}} -> size > 0
      _ -> false
    end
  end

  @doc "Only the extension rule of `check/2`, for one output."
  @spec check_extension(kind(), Path.t()) :: :ok | {:error, Error.t()}
  def check_extension(kind, path), do: extension(kind, path)

  defp extension(kind, path) do
    ext = String.downcase(Path.extname(path))
    allowed = extensions(kind)

    if ext in allowed,
      do: :ok,
      else:
        error(
          kind,
          path,
          "#{noun(kind)} must end in #{Enum.join(allowed, " or ")}, " <>
            "not #{if ext == "", do: "a file without an extension", else: ext}"
        )
  end

  # An existing target (through symlinks) must be a regular file; a
  # dangling symlink or a new name is fine.
  defp target(kind, path) do
    case File.stat(path) do
      {:ok, %File.Stat{type: :regular}} -> :ok
      {:ok, %File.Stat{type: type}} -> error(kind, path, "exists and is a #{type}, not a file")
      {:error, :enoent} -> :ok
      {:error, reason} -> error(kind, path, Error.file_reason(path, reason))
    end
  end

  # The folder must exist and take a new file: tried for real, since
  # permission bits do not tell the whole story (root, ACLs, read-only
  # mounts).
  defp folder(kind, path) do
    dir = Path.dirname(path)

    cond do
      not File.dir?(dir) ->
        error(kind, path, "the folder #{dir} does not exist")

      true ->
        # a hidden file made and removed in the folder opened once
        case fs(Native.fs_probe(Path.expand(path))) do
          {:ok, _} ->
            :ok

          {:error, posix} when is_atom(posix) ->
            error(kind, path, "cannot write in #{dir}: #{Error.file_reason(path, posix)}")

          {:error, message} ->
            error(kind, path, "cannot write in #{dir}: #{message}")
        end
    end
  end

  defp distinct(kind, path, id, seen) do
    case Enum.find(seen, fn {_, _, other} -> other == id end) do
      nil ->
        :ok

      {other_kind, other_path, _} ->
        error(
          kind,
          path,
          "is the same file as #{@option[other_kind]} #{other_path}; " <>
            "each output needs a file of its own"
        )
    end
  end

  defp not_input(kind, path, id, inputs) do
    case Enum.find(inputs, fn {_, input} -> input == id end) do
      nil ->
        :ok

      {input, _} ->
        error(kind, path, "would overwrite #{input}, which this render reads")
    end
  end

  # What a path names: an existing file by device and inode (so symlinks
  # and hard links compare equal), a new one by its folder's and its name.
  defp identity(path) do
    case File.stat(path) do
      {:ok, %File.Stat{major_device: dev, inode: inode}} ->
        {:file, dev, inode}

      _ ->
        case File.stat(Path.dirname(path)) do
          {:ok, %File.Stat{major_device: dev, inode: inode}} ->
            {:new, dev, inode, Path.basename(path)}

          _ ->
            {:path, Path.expand(path)}
        end
    end
  end

  defp noun(:image), do: "the image"
  defp noun(:stats), do: "the statistics"
  defp noun(:timeline), do: "the timeline"
  defp noun(:ownership), do: "the ownership map"

  defp error(kind, path, message),
    do: {:error, Error.new(:file, "#{@option[kind]} #{path}: #{message}")}
end
