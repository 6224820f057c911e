defmodule RingTracer.Error do
  @moduledoc """
  The error RingTracer returns in `{:error, %RingTracer.Error{}}` and raises
  from the `!` functions.

  `:reason` is a machine-readable atom, `:message` says what went wrong and,
  for scene files, where: `scene.nff:12: polygon needs at least 3 vertices`.

  | reason | when |
  |---|---|
  | `:invalid_option` | an option has the wrong type or is out of range |
  | `:file` | a file could not be read or written |
  | `:invalid_scene` | the scene failed to parse (message names file and line) |
  | `:render_failed` | the job could not complete (a crash, a failed atom) |
  | `:timeout` | the render did not finish within `:timeout` |
  | `:cancelled` | `RingTracer.cancel/1` stopped the render |
  | `:not_running` | the `:ring_tracer` application is not running |
  | `:node_unavailable` | a node given in `:nodes` cannot host children (the message says why) |
  | `:cookie` | the cookie file is missing, unsafe (readable by others) or invalid |
  | `:distribution` | this node could not become distributed (name in use, epmd, TLS set-up) |
  | `:preview` | a preview could not start (port in use) or its job is not running |
  """
  defexception [:reason, :message]

  @type t :: %__MODULE__{reason: atom(), message: String.t()}

  @doc false
  @spec new(atom(), String.t()) :: t()
  def new(reason, message) when is_atom(reason) and is_binary(message),
    do: %__MODULE__{reason: reason, message: message}
end
