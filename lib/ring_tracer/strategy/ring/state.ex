defmodule RingTracer.Strategy.Ring.State do
  @moduledoc false
  # A ring child's own state (`RingTracer.Strategy.Ring`): its help offers
  # sent (`seq`, the one out now `current`, the sibling it went to
  # `sent_to`), what it has heard of the fastest siblings (`heard`:
  # `{rate, index, done}`) and, aiming, of their loads (`loads`), the offers
  # it keeps (`parked` while it is idle with its own out, `held` while it
  # traces its last atom) and those to pass on when the message in hand is
  # done (`outbox`: `{to, to_index, offer}`).

  alias RingTracer.Strategy.Ring.{Aim, HelpOffer}

  defstruct seq: 0,
            current: nil,
            sent_to: nil,
            heard: [],
            loads: [],
            parked: [],
            held: [],
            outbox: []

  @type t :: %__MODULE__{
          seq: non_neg_integer(),
          current: pos_integer() | nil,
          sent_to: non_neg_integer() | nil,
          heard: [{float() | nil, non_neg_integer(), non_neg_integer()}],
          loads: [Aim.load()],
          parked: [HelpOffer.t()],
          held: [HelpOffer.t()],
          outbox: [{term(), non_neg_integer(), HelpOffer.t()}]
        }
end
