defmodule RingTracer.Layout do
  @moduledoc false
  # How an image is cut into strips and atoms.
  #
  # The image's pixels are numbered row-major from the top-left, `0..w*h-1`.
  # With `n` children and `k` atoms per child there are `m = n * k` atoms; atom
  # `a` covers pixels `div(a * p, m)` up to (not including) `div((a + 1) * p, m)`
  # where `p = w * h`, so atoms tile the image exactly once for every size, and
  # concatenating atom results in atom order gives the image. When `p < m` some
  # atoms are empty (zero pixels); they are still traced (instantly) and counted.
  #
  # Which atoms a child owns at the start (its strip) is the layout's `order`:
  #
  #   * `:strips` (the paper, the default): child `i`'s strip is atoms
  #     `i*k .. i*k + k - 1`, one contiguous band of the image;
  #   * `:interleaved`: child `i` owns atoms `i, i + n, i + 2n, ...`, bands
  #     spread over the whole image, so every child's share costs about the
  #     same whatever the scene (the sky, the floor and the busy middle).
  #
  # The atoms themselves, and so the image, are the same either way.
  #
  # ## Frames
  #
  # A job of an animation traces several frames through one ring
  # (`with_frames/2`). Every frame is cut alike, and the atoms are numbered
  # on: atom `a` of frame `f` is `f * m + a`, so that atom numbers, pieces and
  # everything that handles them work across frames unchanged. `span/2` is
  # the pixels of an atom within its frame, `frame/2` the frame it is in, and
  # `strip/3` a child's strip in a given frame.
  #
  # ## Pieces
  #
  # An atom can be split at run time (`split/3`): a piece `{a, lo, hi, d}` is
  # parts `lo` up to (not including) `hi` of atom `a` cut into `d` parts, part
  # `j` starting at pixel `first + div(j * count, d)` of the atom's span. A
  # whole atom is its plain index (`{a, 0, 1, 1}` is written `a`). Cutting a
  # piece again refines the same grid, so pieces of one atom always tile it,
  # and a pixel's value does not depend on the span it is traced in
  # (`RingTracer.Kernel`): an image of pieces is the image of atoms, byte for
  # byte.

  @enforce_keys [:width, :height, :children, :atoms_per_child]
  defstruct [:width, :height, :children, :atoms_per_child, order: :strips, frames: 1]

  @typedoc "Which atoms each child owns at the start: see the module doc."
  @type order :: :strips | :interleaved

  @orders [:strips, :interleaved]

  @doc "The orders a layout can have, the default first."
  @spec orders() :: [order()]
  def orders, do: @orders

  @type t :: %__MODULE__{
          width: pos_integer(),
          height: pos_integer(),
          children: pos_integer(),
          atoms_per_child: pos_integer(),
          order: order(),
          frames: pos_integer()
        }
  @typedoc "An atom's index, `0..n*k-1`, or a piece of one (see \"Pieces\")."
  @type atom_id :: non_neg_integer() | piece()

  @typedoc "Parts `lo..hi-1` of atom `a` cut into `d` parts (see \"Pieces\")."
  @type piece ::
          {non_neg_integer(), non_neg_integer(), pos_integer(), pos_integer()}

  @doc """
  A layout for a `width` x `height` image, `children` strips of
  `atoms_per_child` atoms, in `order` (`:strips` or `:interleaved`).
  """
  @spec new(pos_integer(), pos_integer(), pos_integer(), pos_integer(), order()) :: t()
  def new(width, height, children, atoms_per_child, order \\ :strips)
      when is_integer(width) and width > 0 and is_integer(height) and height > 0 and
             is_integer(children) and children > 0 and is_integer(atoms_per_child) and
             atoms_per_child > 0 and order in @orders do
    %__MODULE__{
      width: width,
      height: height,
      children: children,
      atoms_per_child: atoms_per_child,
      order: order
    }
  end

  @doc """
  The same layout for a job of `frames` frames (see "Frames").

      iex> layout = RingTracer.Layout.new(10, 1, 2, 2) |> RingTracer.Layout.with_frames(3)
      iex> {RingTracer.Layout.atom_count(layout), RingTracer.Layout.frame_atom_count(layout)}
      {12, 4}
      iex> RingTracer.Layout.strip(layout, 1, 2)
      [10, 11]
      iex> {RingTracer.Layout.frame(layout, 10), RingTracer.Layout.span(layout, 10), RingTracer.Layout.owner(layout, 10)}
      {2, {5, 2}, 1}
      iex> RingTracer.Layout.frame_atoms(layout, 1)
      4..7
  """
  @spec with_frames(t(), pos_integer()) :: t()
  def with_frames(%__MODULE__{} = layout, frames) when is_integer(frames) and frames > 0,
    do: %{layout | frames: frames}

  @doc "Number of pixels (of one frame)."
  @spec pixels(t()) :: non_neg_integer()
  def pixels(%__MODULE__{width: w, height: h}), do: w * h

  @doc "Total number of atoms, of every frame."
  @spec atom_count(t()) :: pos_integer()
  def atom_count(%__MODULE__{frames: f} = layout), do: f * frame_atom_count(layout)

  @doc "Number of atoms of one frame."
  @spec frame_atom_count(t()) :: pos_integer()
  def frame_atom_count(%__MODULE__{children: n, atoms_per_child: k}), do: n * k

  @doc "Every atom index, frame after frame, each in image order."
  @spec atoms(t()) :: Range.t()
  def atoms(layout), do: 0..(atom_count(layout) - 1)

  @doc "The atoms of frame `f` (from 0), in image order."
  @spec frame_atoms(t(), non_neg_integer()) :: Range.t()
  def frame_atoms(layout, f) do
    m = frame_atom_count(layout)
    (f * m)..(f * m + m - 1)
  end

  @doc "The frame (from 0) atom or piece `a` belongs to."
  @spec frame(t(), atom_id()) :: non_neg_integer()
  def frame(layout, a), do: div(base(a), frame_atom_count(layout))

  @doc """
  The atoms of child `i`'s strip in frame `f` (the first by default), in image order.

      iex> layout = RingTracer.Layout.new(10, 1, 2, 2)
      iex> Enum.map(RingTracer.Layout.atoms(layout), &RingTracer.Layout.span(layout, &1))
      [{0, 2}, {2, 3}, {5, 2}, {7, 3}]
      iex> RingTracer.Layout.strip(layout, 1)
      [2, 3]
      iex> RingTracer.Layout.strip(RingTracer.Layout.new(10, 1, 2, 2, :interleaved), 1)
      [1, 3]
  """
  @spec strip(t(), non_neg_integer(), non_neg_integer()) :: [atom_id()]
  def strip(layout, i, f \\ 0)

  def strip(%__MODULE__{children: n, atoms_per_child: k, order: :strips}, i, f)
      when i in 0..(n - 1)//1,
      do: Enum.to_list((f * n * k + i * k)..(f * n * k + i * k + k - 1))

  def strip(%__MODULE__{children: n, atoms_per_child: k, order: :interleaved}, i, f)
      when i in 0..(n - 1)//1,
      do: Enum.to_list((f * n * k + i)..(f * n * k + i + (k - 1) * n)//n)

  @doc "The child whose strip holds atom `a` (its original owner)."
  @spec owner(t(), atom_id()) :: non_neg_integer()
  def owner(layout, {a, _, _, _}), do: owner(layout, a)

  def owner(%__MODULE__{atoms_per_child: k, order: :strips} = layout, a),
    do: div(rem(a, frame_atom_count(layout)), k)

  def owner(%__MODULE__{children: n, order: :interleaved}, a), do: rem(a, n)

  @doc """
  Each atom's share of per-row work (`rows`: one number per image row, top
  first): from every row it covers, the row's work times the fraction of
  the row's pixels it holds. A tuple, by atom of one frame.

      iex> layout = RingTracer.Layout.new(4, 2, 2, 2)
      iex> RingTracer.Layout.work_by_atom(layout, {8, 4})
      {4.0, 4.0, 2.0, 2.0}
      iex> RingTracer.Layout.work_by_atom(RingTracer.Layout.new(4, 2, 1, 3), {8, 4})
      {4.0, 5.0, 3.0}
  """
  @spec work_by_atom(t(), tuple()) :: tuple()
  def work_by_atom(%__MODULE__{width: w, height: h} = layout, rows) when tuple_size(rows) == h do
    for a <- frame_atoms(layout, 0) do
      {first, count} = span(layout, a)
      last = first + count - 1

      Enum.reduce(div(first, w)..div(last, w)//1, 0.0, fn r, acc ->
        covered = min(last, r * w + w - 1) - max(first, r * w) + 1
        acc + elem(rows, r) * covered / w
      end)
    end
    |> List.to_tuple()
  end

  @doc "`{first_pixel, pixel_count}` of atom (or piece) `a` within its frame."
  @spec span(t(), atom_id()) :: {non_neg_integer(), non_neg_integer()}
  def span(layout, {a, lo, hi, d}) do
    {first, count} = span(layout, a)
    {first + div(lo * count, d), div(hi * count, d) - div(lo * count, d)}
  end

  def span(layout, a) do
    m = frame_atom_count(layout)
    p = pixels(layout)
    a = rem(a, m)
    first = div(a * p, m)
    {first, div((a + 1) * p, m) - first}
  end

  @doc """
  The atom a piece belongs to (an atom is its own).

      iex> {RingTracer.Layout.base(5), RingTracer.Layout.base({5, 1, 2, 4})}
      {5, 5}
  """
  @spec base(atom_id()) :: non_neg_integer()
  def base({a, _, _, _}), do: a
  def base(a) when is_integer(a), do: a

  @doc """
  An atom or piece as people read it.

      iex> {RingTracer.Layout.name(5), RingTracer.Layout.name({5, 1, 3, 4})}
      {"5", "5 (parts 1-2 of 4)"}
  """
  @spec name(atom_id()) :: String.t()
  def name({a, lo, hi, d}), do: "#{a} (parts #{lo}-#{hi - 1} of #{d})"
  def name(a) when is_integer(a), do: Integer.to_string(a)

  @doc """
  The share of its atom a piece covers, `{numerator, denominator}` (an atom:
  `{1, 1}`).

      iex> RingTracer.Layout.fraction({5, 1, 3, 4})
      {2, 4}
  """
  @spec fraction(atom_id()) :: {pos_integer(), pos_integer()}
  def fraction({_, lo, hi, d}), do: {hi - lo, d}
  def fraction(a) when is_integer(a), do: {1, 1}

  @doc """
  Atom or piece `a` cut in two: its first `k` of `n` equal parts, and the
  rest (`0 < k < n`). The pieces are written with the smallest grid (a
  piece that is a whole atom is its index).

      iex> layout = RingTracer.Layout.new(10, 1, 1, 1)
      iex> {head, tail} = RingTracer.Layout.split(0, 3, 4)
      iex> {head, tail}
      {{0, 0, 3, 4}, {0, 3, 4, 4}}
      iex> {RingTracer.Layout.span(layout, head), RingTracer.Layout.span(layout, tail)}
      {{0, 7}, {7, 3}}
      iex> RingTracer.Layout.split(tail, 1, 2)
      {{0, 6, 7, 8}, {0, 7, 8, 8}}
  """
  @spec split(atom_id(), pos_integer(), pos_integer()) :: {atom_id(), atom_id()}
  def split(a, k, n) when is_integer(k) and is_integer(n) and k > 0 and k < n,
    do: {parts(a, 0, k, n), parts(a, k, n, n)}

  @doc """
  Parts `from` up to (not including) `to` of atom or piece `a` cut into `n`
  equal parts (`0 <= from < to <= n`), with the smallest grid, as
  `split/3` writes them: a grandchild traces a long atom part by part
  (`RingTracer.Job.Grandchild`), and its child may cut off the parts not
  yet started.

      iex> RingTracer.Layout.parts(3, 2, 4, 8)
      {3, 1, 2, 4}
      iex> RingTracer.Layout.parts({3, 1, 2, 4}, 0, 1, 2)
      {3, 2, 3, 8}
      iex> RingTracer.Layout.parts({3, 1, 2, 4}, 0, 4, 4)
      {3, 1, 2, 4}
  """
  @spec parts(atom_id(), non_neg_integer(), pos_integer(), pos_integer()) :: atom_id()
  def parts(a, from, to, n) when is_integer(a), do: parts({a, 0, 1, 1}, from, to, n)

  def parts({a, lo, hi, d}, from, to, n)
      when is_integer(n) and is_integer(from) and is_integer(to) and 0 <= from and from < to and
             to <= n,
      do: piece(a, lo * n + from * (hi - lo), lo * n + to * (hi - lo), d * n)

  defp piece(a, 0, d, d), do: a

  defp piece(a, lo, hi, d) do
    g = Integer.gcd(Integer.gcd(lo, hi), d)
    {a, div(lo, g), div(hi, g), div(d, g)}
  end
end
