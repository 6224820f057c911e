defmodule RingTracer.Kernel.Simulated do
  # An atom's cost, in microseconds, when none is given.
  @default_cost 2000

  @moduledoc false
  # A cost model in place of the ray tracer: each atom "costs" some
  # microseconds, and tracing it is sleeping that long (no CPU burnt), then
  # returning black pixels of the right size. The same parent, children and
  # strategies run on it, so a ring of 1024 children fits on a small machine.
  #
  # ## Options
  #
  #   * `:costs` — per-atom costs in microseconds: a list or tuple indexed by
  #     atom (for instance the `:trace_us` of a real render's `:atoms`), a
  #     binary of native-endian unsigned 32-bit integers (what `RingTracer.simulate/1`
  #     turns a list or tuple into, so that 1024 children share one copy), a
  #     function `atom -> microseconds`, or one integer for every atom
  #     (default #{@default_cost}).
  #
  # In a job of several frames (`RingTracer.Layout`, "Frames") every frame
  # costs alike: costs are indexed by the atom within its frame.
  @behaviour RingTracer.Kernel

  alias RingTracer.Layout

  defmodule Frames do
    @moduledoc false
    # The context of a job of several frames: the costs, and the layout's
    # atoms per frame.
    @enforce_keys [:costs, :frame_atoms]
    defstruct @enforce_keys

    @type t :: %__MODULE__{costs: term(), frame_atoms: pos_integer()}
  end

  @doc "An atom's cost when none is given, in microseconds."
  @spec default_cost() :: pos_integer()
  def default_cost, do: @default_cost

  @impl RingTracer.Kernel
  def prepare(%{layout: %Layout{frames: 1}}, opts),
    do: {:ok, Keyword.get(opts, :costs, @default_cost)}

  def prepare(spec, opts) do
    {:ok,
     %Frames{
       costs: Keyword.get(opts, :costs, @default_cost),
       frame_atoms: Layout.frame_atom_count(spec.layout)
     }}
  end

  @doc """
  Costs in their shared form: a list or tuple becomes one binary (referenced,
  not copied, by every process on the node).

      iex> costs = RingTracer.Kernel.Simulated.pack([5, 7])
      iex> {RingTracer.Kernel.Simulated.cost(costs, 1), RingTracer.Kernel.Simulated.cost(costs, 2)}
      {7, 5}
  """
  @spec pack(term()) :: term()
  def pack(costs) when is_tuple(costs), do: pack(Tuple.to_list(costs))

  def pack(costs) when is_list(costs),
    do: for(c <- costs, into: <<>>, do: <<c::unsigned-native-32>>)

  def pack(costs), do: costs

  @impl RingTracer.Kernel
  def prepare_node(_spec, _opts, _owner), do: :ok

  @doc "Each atom's work, of one frame: its cost in the model (an exact preview)."
  @impl RingTracer.Kernel
  def atom_work(spec, opts) do
    costs = Keyword.get(opts, :costs, @default_cost)
    {:ok, List.to_tuple(for a <- Layout.frame_atoms(spec.layout, 0), do: cost(costs, a))}
  end

  @impl RingTracer.Kernel
  def trace(%Frames{costs: costs, frame_atoms: m}, _first, count, atom),
    do: sleep(costs, rem(Layout.base(atom), m), count, atom)

  def trace(costs, _first, count, atom), do: sleep(costs, Layout.base(atom), count, atom)

  # Atom or piece `atom`, atom `index` of the costs, of `count` pixels.
  defp sleep(costs, index, count, atom) do
    # A piece of an atom (`RingTracer.Layout`) costs its share of the atom.
    {k, n} = Layout.fraction(atom)
    us = div(cost(costs, index) * k, n)
    t0 = System.monotonic_time(:microsecond)
    Process.sleep(div(us + 500, 1000))
    elapsed = System.monotonic_time(:microsecond) - t0
    # Its work units are the model's microseconds: what the atom costs on a
    # machine of speed 1.
    {:ok, :binary.copy(<<0::96>>, count), %{RingTracer.Rays.zero() | work: us}, elapsed}
  end

  @doc "The cost in microseconds of `atom` under `costs`."
  @spec cost(
          tuple() | (non_neg_integer() -> non_neg_integer()) | non_neg_integer(),
          non_neg_integer()
        ) ::
          non_neg_integer()
  def cost(costs, atom) when is_binary(costs) do
    offset = rem(atom, div(byte_size(costs), 4)) * 4
    <<_::binary-size(offset), us::unsigned-native-32, _::binary>> = costs
    us
  end

  def cost(costs, atom) when is_tuple(costs), do: elem(costs, rem(atom, tuple_size(costs)))
  def cost(costs, atom) when is_function(costs, 1), do: costs.(atom)
  def cost(costs, _atom) when is_integer(costs), do: costs
end
