"""A peer's clock offset from NTP-style exchanges (pure): each exchange gives four timestamps;
the estimate is the median offset of the window's faster half (the exchanges whose round trip is
at most the window's median), kept inside the interval every exchange of the window allows.

    local  t1 ----------------------------------------> t4       (this process's clock)
                 \\                                     /
    peer          t2 (received) ...held... t3 (sent)            (the peer's clock)

    offset = ((t2 - t1) + (t3 - t4)) / 2      the peer's clock minus ours
    rtt    = (t4 - t1) - (t3 - t2)            the time on the wire, both ways

One exchange's offset errs by half the difference of its two legs, at most rtt / 2 whatever
the asymmetry, so the true offset lies in [offset - rtt / 2, offset + rtt / 2] of every exchange
and in their intersection. Why the median and not NTP's single least round trip: when the two
legs jitter independently and alike (a radio mesh, netem's normal jitter), the difference of
the legs is independent of their sum, so the fastest exchange errs as much as any other (by the
jitter's standard deviation / sqrt 2), while the median of many converges on the true offset.
The faster half keeps the median clear of one direction's queueing, where the least round trip
is the better estimate; the intersection bounds what either may do. Where peers must agree on
an instant rather than each be within a bound of the truth, the median before the bound
(`median_offset_s`) is the one to use: on a path whose jitter is all on one leg the bound's
edge is an extreme of the window, which differs from one peer to the next by milliseconds.
Where the window's exchanges contradict each other (no offset lies in every one's interval: a
clock stepped, or drifted further than the older exchanges allow), the newest exchanges that
agree make the estimate, so it follows the clock as it is now.

In the agents' exchange, t1 is a sample's `sent_s` that the peer echoes back with
`held_s = t3 - t2` in its own sample sent at t3, received here at t4. The peer echoes every
message it received, once (gcs/agent/table.py): echoing only its latest would favour the
messages that arrived early, and bias the offset by a fraction of the jitter.
"""

from __future__ import annotations

import math

import numpy as np

#: A round trip this far below zero is rounding (timestamps of ~1e6 s differ in the 1e-10 s);
#: it is taken as 0. Further below, the four timestamps cannot be one exchange.
RTT_ROUNDING_S = 1e-6


class OffsetEstimator:
    """One peer's clock offset: `add` each exchange; the estimate is over the last `window`
    exchanges no older than `max_age_s` (by our clock, at the newest)."""

    def __init__(self, window: int = 512, max_age_s: float = 30.0) -> None:
        if window < 1 or not max_age_s > 0.0:
            raise ValueError(f"window {window} must be >= 1 and max_age_s {max_age_s} > 0")
        self.window, self.max_age_s = window, max_age_s
        # a ring of the last `window` exchanges: offset, round trip, our time of arrival
        self._ring = np.full((3, window), np.nan)
        self._next = 0
        # offset, bound, least rtt, the faster half's median before it is kept in the bound,
        # and the interval's low and high ends
        self._estimate: tuple[float, float, float, float, float, float] | None = None
        self._stale = False
        self.total = 0  # exchanges accepted since the start or the last reset
        self.refused = 0  # exchanges refused: not finite, or a negative round trip

    def add(self, t1_s: float, t2_s: float, t3_s: float, t4_s: float) -> bool:
        """Take one exchange (module docstring); False if it is refused: a timestamp that is not
        finite, or a round trip below zero by more than RTT_ROUNDING_S (timestamps that cannot
        be one exchange)."""
        if not all(math.isfinite(t) for t in (t1_s, t2_s, t3_s, t4_s)):
            self.refused += 1
            return False
        rtt = (t4_s - t1_s) - (t3_s - t2_s)
        if rtt < -RTT_ROUNDING_S:
            self.refused += 1
            return False
        slot = self._next % self.window
        self._ring[:, slot] = (((t2_s - t1_s) + (t3_s - t4_s)) / 2.0, max(rtt, 0.0), t4_s)
        self._next += 1
        self.total += 1
        self._stale = True
        return True

    def reset(self) -> None:
        """Forget every exchange (the peer restarted: its clock may be another)."""
        self._ring[:] = np.nan
        self._next = 0
        self._estimate = None
        self._stale = False
        self.total = 0

    def _window(self) -> np.ndarray:
        """The exchanges in the window, (3, k): offset, rtt, arrival."""
        ring = self._ring[:, :min(self._next, self.window)]
        if ring.shape[1] == 0:
            return ring
        return ring[:, ring[2] >= np.max(ring[2]) - self.max_age_s]

    def _current(self) -> tuple[float, float, float, float, float, float] | None:
        if self._stale:
            self._stale = False
            offset, rtt, arrival = self._window()
            low, high = offset - rtt / 2.0, offset + rtt / 2.0
            if np.max(low) > np.min(high) + RTT_ROUNDING_S:
                # exchanges that contradict each other: the peer's clock (or ours) stepped or
                # drifted past what the older ones allow; keep the newest that agree
                newest = np.argsort(arrival)[::-1]
                agree = (np.maximum.accumulate(low[newest])
                         <= np.minimum.accumulate(high[newest]) + RTT_ROUNDING_S)
                keep = newest[:int(np.argmin(agree)) if not agree.all() else len(agree)]
                offset, rtt, low, high = offset[keep], rtt[keep], low[keep], high[keep]
            faster = offset[rtt <= np.median(rtt)]
            median = float(np.median(faster))
            lo, hi = float(np.max(low)), float(np.min(high))
            estimate = min(max(median, lo), hi)  # kept inside what every exchange allows
            bound = max(estimate - lo, hi - estimate, 0.0)
            self._estimate = (estimate, bound, float(np.min(rtt)), median, lo, hi)
        return self._estimate

    @property
    def samples(self) -> int:
        """Exchanges in the window."""
        return self._window().shape[1]

    @property
    def offset_s(self) -> float | None:
        """The peer's clock minus ours [s], None before the first exchange."""
        current = self._current()
        return None if current is None else current[0]

    @property
    def median_offset_s(self) -> float | None:
        """The median offset of the window's faster half, before it is kept inside the interval
        every exchange allows (the peer's clock minus ours [s]; None before the first exchange;
        newest agreeing exchanges' when the window's contradict each other). On a path whose
        jitter is all on one leg the interval's edge is the least delay of that leg, an extreme
        of the window that moves by milliseconds from one peer to the next while their medians
        stay within a fraction of one: use this where peers on alike paths must agree on an
        instant, `offset_s` where the error to the true offset must stay bounded."""
        current = self._current()
        return None if current is None else current[3]

    @property
    def rtt_s(self) -> float | None:
        """The least round trip in the window (of its newest agreeing exchanges, when they
        contradict each other) [s], None before the first exchange."""
        current = self._current()
        return None if current is None else current[2]

    @property
    def uncertainty_s(self) -> float | None:
        """A bound on the offset's error [s]: the estimate's distance to the far end of the
        interval every exchange in the window allows (at most the least round trip); None
        before the first exchange."""
        current = self._current()
        return None if current is None else current[1]

    @property
    def interval_s(self) -> tuple[float, float] | None:
        """The offsets every exchange in the window allows, (low, high) [s] (of the newest
        exchanges that agree, when the window's contradict each other); None before the first
        exchange. The true offset lies inside whatever the paths' asymmetry: only its width
        depends on it."""
        current = self._current()
        return None if current is None else (current[4], current[5])

    def to_local(self, peer_s: float) -> float:
        """Time `peer_s` of the peer's clock on ours; LookupError before the first exchange."""
        current = self._current()
        if current is None:
            raise LookupError("no clock offset measured yet: no exchange with the peer")
        return peer_s - current[0]
