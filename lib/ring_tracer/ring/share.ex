defmodule RingTracer.Ring.Share do
  @moduledoc """
  The help-offer share rule: how many atoms a child gives to a sibling that
  offered help.

  The paper has the receiver compare the offerer's count of computed atoms
  with its own to estimate their relative speed. Both counts run from the
  start of the job, so over the same elapsed time they are proportional to
  speed: `v_offerer / v_self = done_offerer / done_self`.

  The giver still has to finish `in_flight` atoms already in its grandchild's
  pipe plus `remaining` queued ones. It gives `g` of the queued ones so that
  both finish at about the same time:

      (remaining + in_flight - g) / v_self = g / v_offerer
      g = floor((remaining + in_flight) * done_offerer / (done_offerer + done_self))

  capped at `remaining` (atoms in flight are never taken back). A result of 0
  means "not worth it": the offer is passed on. A child that has computed
  nothing yet is treated as having computed nothing (`done_self = 0`): the
  offerer is faster than it, so it gives all it can. An offerer that has
  computed nothing (its strip was all given away) counts as 1 so that it
  still gets a share.

      iex> RingTracer.Ring.Share.give(10, 0, 5, 5)
      5
      iex> RingTracer.Ring.Share.give(10, 0, 1, 3)
      2
      iex> RingTracer.Ring.Share.give(1, 1, 4, 4)
      1
      iex> RingTracer.Ring.Share.give(0, 2, 4, 4)
      0
  """

  @doc """
  Atoms to give: `remaining` queued atoms, `in_flight` atoms in the pipe,
  the offerer's `offerer_done` and the giver's `self_done` counts.
  """
  @spec give(non_neg_integer(), non_neg_integer(), non_neg_integer(), non_neg_integer()) ::
          non_neg_integer()
  def give(remaining, in_flight, offerer_done, self_done)
      when is_integer(remaining) and remaining >= 0 and is_integer(in_flight) and in_flight >= 0 and
             is_integer(offerer_done) and offerer_done >= 0 and is_integer(self_done) and
             self_done >= 0 do
    v_offerer = max(offerer_done, 1)
    share = div((remaining + in_flight) * v_offerer, v_offerer + self_done)
    min(share, remaining)
  end
end
