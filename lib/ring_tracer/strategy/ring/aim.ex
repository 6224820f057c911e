defmodule RingTracer.Strategy.Ring.Aim do
  @loads_max 3
  @known_max 8
  @board_to 2

  @moduledoc false
  # Aiming (our addition to the paper): where an idle child sends its help
  # offer.
  #
  # The paper sends every offer to the left sibling. On the paper's strips that
  # drains the cheap work first: with speeds 1..8 in child order, the fastest
  # child, done with the sky, helps its left neighbours, the slowest children,
  # whose strips are cheap too, while the expensive middle strips stay with
  # their owners and move last, in expensive atoms that end the job late. So an
  # idle child sends its offer straight to the sibling it expects to stay busy
  # longest, if that is not its left sibling anyway. A sibling so aimed at
  # consumes the offer as any other; if it has nothing to give (a miss), it
  # sends the offer on to its origin's left sibling (which the offer names),
  # as if the origin had sent it there, and from there it walks the ring as
  # the paper's offers do: a child is still finished only once an offer of
  # its own has asked every sibling. (Sending a miss back to its origin,
  # which then sent a new offer, cost one message more per miss.)
  #
  # ## What a child knows
  #
  # *Loads*: `{index, end_us, at_us, queued}`, an estimate made at job time
  # `at_us` of when a sibling will have traced everything it holds (`end_us`)
  # and how many atoms it had queued. A child's own: its queued atoms times its
  # mean time per atom, plus what its atom in flight should still take. Offers
  # carry the 3 (`@loads_max`) latest-ending loads their children know of, and so do
  # hand-overs (the giver's own load, just lowered, first among them); every
  # child an offer or a hand-over reaches adds its own and keeps the 8 (`@known_max`)
  # latest-ending ones, the newest report per sibling. A report ages: by the
  # time per atom it implies, the sibling has started atoms since, and one
  # that should have no atom queued any more is not aimed at.
  #
  # *The board*: before any offer has been anywhere, nobody knows anything,
  # and the first offers of a job decide where the middle strips go. So the
  # parent, which receives every atom, makes one board once each child has
  # sent it an atom: for each child, the work left in its own atoms (from a
  # preview of the image, the kernel's optional `atom_work/2`) over the work
  # per microsecond it has delivered so far. It sends it only to the 2 (`@board_to`)
  # children expected to run out first, the first to offer; their offers
  # carry it on. (Sending it to every child cost more messages in misses than
  # it saved, measured on `8, speeds 1..8`.)

  alias RingTracer.Layout

  @typedoc """
  A sibling's index, its expected end and when that was said (job
  microseconds), and its atoms queued then.
  """
  @type load ::
          {non_neg_integer(), integer(), integer(), non_neg_integer()}

  @doc """
  `known` with `news` added: the newest report per sibling (by `at_us`), the
  #{@known_max} latest-ending first.
  """
  @spec learn([load()], [load()]) :: [load()]
  def learn(known, news) do
    (news ++ known)
    |> Enum.group_by(&elem(&1, 0))
    |> Enum.map(fn {_, reports} -> Enum.max_by(reports, &elem(&1, 2)) end)
    |> Enum.sort_by(&{-elem(&1, 1), elem(&1, 0)})
    |> Enum.take(@known_max)
  end

  @doc """
  What an offer or a hand-over carries of `known`: its #{@loads_max}
  latest-ending loads, and `first` (a child's own) ahead of them.

      iex> RingTracer.Strategy.Ring.Aim.news([{4, 90, 0, 2}, {5, 80, 0, 2}, {6, 70, 0, 2}, {7, 60, 0, 2}])
      [{4, 90, 0, 2}, {5, 80, 0, 2}, {6, 70, 0, 2}]
      iex> RingTracer.Strategy.Ring.Aim.news([{4, 90, 0, 2}, {5, 80, 0, 2}, {6, 70, 0, 2}], {1, 10, 5, 0})
      [{1, 10, 5, 0}, {4, 90, 0, 2}, {5, 80, 0, 2}, {6, 70, 0, 2}]
  """
  @spec news([load()], load() | nil) :: [load()]
  def news(known, first \\ nil)
  def news(known, nil), do: Enum.take(known, @loads_max)

  def news(known, {i, _, _, _} = first),
    do: [first | known |> Enum.reject(&(elem(&1, 0) == i)) |> Enum.take(@loads_max)]

  @doc """
  The sibling an idle child should send its offer to, or `nil` for its left
  sibling. `view`: the child's `index`, `left_index`, `dead` siblings, job
  time `now` and `min_us` (its mean time per atom: a sibling ending sooner
  than that is not worth the detour). Of the siblings that should still have
  an atom queued (`queued?/2`), the one that should end last wins; below,
  sibling 1 ends later, but by its report it has started its one queued atom
  since.

      iex> view = %{index: 0, left_index: 3, dead: [], now: 1_000, min_us: 100}
      iex> known = [{1, 5_000, 0, 1}, {2, 3_000, 900, 2}]
      iex> RingTracer.Strategy.Ring.Aim.target(known, view)
      2
      iex> RingTracer.Strategy.Ring.Aim.target(known, %{view | dead: [2]})
      nil

  What a child knows (`learn/2`, latest-ending first) decides:

    iex> alias RingTracer.Strategy.Ring.Aim
    iex> known = Aim.learn([{1, 900, 100, 3}], [{1, 500, 200, 1}, {2, 800, 150, 4}])
    [{2, 800, 150, 4}, {1, 500, 200, 1}]
    iex> view = %{index: 0, left_index: 3, dead: [], now: 300, min_us: 100}
    iex> Aim.target(known, view)
    2
    iex> Aim.target(known, %{view | left_index: 2})
    nil
  """
  @spec target([load()], map()) :: non_neg_integer() | nil
  def target(known, view) do
    candidates =
      for {i, end_us, _, _} = load <- known,
          i != view.index,
          i not in view.dead,
          queued?(load, view.now),
          do: {end_us, i}

    case Enum.max(candidates, fn -> nil end) do
      {end_us, i} when end_us > view.now + view.min_us and i != view.left_index -> i
      _ -> nil
    end
  end

  @doc """
  Whether a sibling should still have an atom queued at job time `now`, by
  its report: `queued` atoms then, and one in flight, that were to take until
  `end_us`; since `at_us` it has started one atom per (end_us - at_us) /
  (queued + 1).

      iex> RingTracer.Strategy.Ring.Aim.queued?({1, 4_000, 0, 3}, 1_000)
      true
      iex> RingTracer.Strategy.Ring.Aim.queued?({1, 4_000, 0, 3}, 3_000)
      false
      iex> RingTracer.Strategy.Ring.Aim.queued?({1, 4_000, 0, 0}, 0)
      false
  """
  @spec queued?(load(), integer()) :: boolean()
  def queued?({_, end_us, at_us, queued}, now) do
    per_atom = max(end_us - at_us, 1) / (queued + 1)
    queued - max(now - at_us, 0) / per_atom >= 1
  end

  @doc """
  The parent's board at job time `now`: for each child, its own atoms not yet
  traced (by anyone) and their estimated `work` (a tuple by atom), over the
  work per microsecond the child has traced so far (`traced_by`: atom to
  child), latest-ending first; and the #{@board_to} children to send it to,
  those expected to run out first. A child that has traced no work yet is
  left out.

      iex> layout = RingTracer.Layout.new(4, 2, 2, 2)
      iex> traced_by = %{0 => 0, 2 => 1}
      iex> RingTracer.Strategy.Ring.Aim.board(layout, {10, 10, 40, 80}, traced_by, 100)
      {[{1, 300, 100, 1}, {0, 200, 100, 1}], [1, 0]}
  """
  @spec board(Layout.t(), tuple(), %{Layout.atom_id() => non_neg_integer()}, integer()) ::
          {[load()], [non_neg_integer()]}
  def board(layout, work, traced_by, now) do
    done =
      Enum.reduce(traced_by, %{}, fn {a, i}, acc ->
        {k, n} = Layout.fraction(a)
        w = elem(work, Layout.base(a)) * k / n
        Map.update(acc, i, w, &(&1 + w))
      end)

    traced = MapSet.new(Map.keys(traced_by), &Layout.base/1)

    loads =
      for i <- 0..(layout.children - 1), rate = Map.get(done, i, 0) / max(now, 1), rate > 0 do
        left = Enum.reject(Layout.strip(layout, i), &MapSet.member?(traced, &1))
        left_work = Enum.reduce(left, 0, &(elem(work, &1) + &2))
        {i, now + round(left_work / rate), now, length(left)}
      end
      |> Enum.sort_by(&{-elem(&1, 1), elem(&1, 0)})

    to = loads |> Enum.take(-@board_to) |> Enum.map(&elem(&1, 0))
    {Enum.take(loads, @known_max), to}
  end
end
