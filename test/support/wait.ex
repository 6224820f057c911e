defmodule RingTracer.Test.Wait do
  @moduledoc "Waiting, boundedly, for something another process does asynchronously."

  @doc "Whether `fun` returns true within `tries` tries 10 ms apart."
  @spec eventually((() -> boolean()), non_neg_integer()) :: boolean()
  def eventually(fun, tries \\ 200) do
    cond do
      fun.() -> true
      tries == 0 -> false
      true -> sleep_then(fn -> eventually(fun, tries - 1) end)
    end
  end

  defp sleep_then(fun) do
    Process.sleep(10)
    fun.()
  end
end
