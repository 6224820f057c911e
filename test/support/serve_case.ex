defmodule RingTracer.Test.ServeCase do
  @moduledoc """
  The case of the `ringtracer serve` test modules: the `:distributed` tag, a
  long timeout, `RingTracer.Test.Serve`'s helpers and `PortOutput`'s
  imported, and the module's private folder (`Serve.folder/0`) in the context.
  """
  use ExUnit.CaseTemplate

  using do
    quote do
      import RingTracer.Test.PortOutput, only: [collect: 1, until: 2], warn: false
      import RingTracer.Test.Serve, warn: false

      alias RingTracer.Test.Serve

      @moduletag :distributed
      @moduletag timeout: 240_000
    end
  end

  setup_all do
    {:ok, RingTracer.Test.Serve.folder()}
  end
end
