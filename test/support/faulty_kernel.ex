defmodule RingTracer.Test.FaultyKernel do
  @moduledoc """
  A test-only kernel: the native one, except that an atom holding pixel
  `:fail_pixel` fails as a kernel panic does (`RingTracer.Kernel.Native`
  turns a panic into `{:error, "kernel raised: ..."}`), every time it is
  traced; an atom holding pixel `:short_pixel` comes back a pixel short,
  as a kernel with a bug would give it; and, with `:jitter`, each atom's result waits up to that many
  milliseconds more, drawn at random, before it goes to its child (and
  `:delay` milliseconds more, always); and, with
  `freeze: {node, os_pid}`, that node's OS process is stopped (SIGSTOP) as
  the parent prepares it, as a node that hangs while a job starts; and,
  with `block: {node, nth, pid, ref}`, the `nth` atom traced on that node
  under `ref` (counted across the jobs that use `ref`: a job started
  again does not block again) is held: its grandchild sends
  `{:blocked, ref, grandchild}` to `pid` and waits until it gets
  `{:release, ref}` or is killed (with its child), so that the child
  holding it cannot finish, and the job cannot end, before the test acts.
  `block_first: {node, pid, ref}` is `block: {node, 1, pid, ref}`.
  """
  @behaviour RingTracer.Kernel

  alias RingTracer.Kernel.Native

  @impl true
  def prepare(spec, opts) do
    with {:ok, context} <- Native.prepare(spec, []), do: {:ok, {context, opts}}
  end

  @impl true
  def prepare_node(spec, opts, owner) do
    case opts[:freeze] do
      {node, os_pid} when node == node() -> {_, 0} = System.cmd("kill", ["-STOP", os_pid])
      _ -> :ok
    end

    # One count per ref on the node, of the atoms traced there.
    case block(opts) do
      {node, _nth, _pid, ref} when node == node() ->
        if :persistent_term.get({__MODULE__, ref}, nil) == nil,
          do: :persistent_term.put({__MODULE__, ref}, :atomics.new(1, []))

      _ ->
        :ok
    end

    Native.prepare_node(spec, [], owner)
  end

  @impl true
  def atom_work(spec, _opts), do: Native.atom_work(spec, [])

  @impl true
  def trace({context, opts}, first, count, atom) do
    block_if_nth(block(opts))
    pixel = opts[:fail_pixel]

    holds? = fn p -> is_integer(p) and p >= first and p < first + count end

    result =
      cond do
        holds?.(pixel) ->
          {:error, "kernel raised: test fault at pixel #{pixel}"}

        holds?.(opts[:short_pixel]) ->
          {:ok, pixels, rays, us} = Native.trace(context, first, count, atom)
          {:ok, binary_part(pixels, 0, byte_size(pixels) - 12), rays, us}

        true ->
          Native.trace(context, first, count, atom)
      end

    case Keyword.get(opts, :jitter, 0) do
      0 -> :ok
      max -> Process.sleep(:rand.uniform(max + 1) - 1)
    end

    Process.sleep(Keyword.get(opts, :delay, 0))

    result
  end

  defp block(opts) do
    case opts[:block_first] do
      {node, pid, ref} -> {node, 1, pid, ref}
      nil -> opts[:block]
    end
  end

  defp block_if_nth({node, nth, pid, ref}) when node == node() do
    count = :persistent_term.get({__MODULE__, ref})

    if :atomics.add_get(count, 1, 1) == nth do
      send(pid, {:blocked, ref, self()})

      receive do
        {:release, ^ref} -> :ok
      end
    end
  end

  defp block_if_nth(_), do: :ok

  @doc """
  The render child that spawned `grandchild` (a blocked one): the
  process it is linked to under `RingTracer.Children`, on its node.
  """
  @spec child_of(pid()) :: pid()
  def child_of(grandchild),
    do: :erpc.call(node(grandchild), __MODULE__, :local_child_of, [grandchild])

  @doc false
  def local_child_of(grandchild) do
    {:links, links} = Process.info(grandchild, :links)
    children = DynamicSupervisor.which_children(RingTracer.Children)
    [child] = for {_, pid, _, _} <- children, pid in links, do: pid
    child
  end
end
