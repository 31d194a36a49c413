"""A peer's clock offset from NTP-style exchanges (pure): each exchange gives four timestamps,
the estimate is the exchange with the least round trip in a sliding window (NTP's clock
filter, RFC 5905 section 10), and its uncertainty is half that round trip.

    local  t1 ----------------------------------------> t4       (this process's clock)
                 \\                                     /
    peer          t2 (received) ...held... t3 (sent)            (the peer's clock)

    offset = ((t2 - t1) + (t3 - t4)) / 2      the peer's clock minus ours
    rtt    = (t4 - t1) - (t3 - t2)            the time on the wire, both ways

The offset's error is at most rtt / 2 whatever the asymmetry of the two legs, so the least
round trip bounds it tightest. In the agents' exchange, t1 is a sample's `sent_s` that the peer
echoes back with `held_s = t3 - t2` in its own sample sent at t3, received here at t4.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: A round trip this far below zero is rounding (timestamps of ~1e6 s differ in the 1e-10 s);
#: it is taken as 0. Further below, the four timestamps cannot be one exchange.
RTT_ROUNDING_S = 1e-6


@dataclass(frozen=True, slots=True)
class Exchange:
    """One exchange: the peer's offset (its clock - ours) and the round trip it was measured
    over, received at `at_s` (our clock)."""

    offset_s: float
    rtt_s: float
    at_s: float


class OffsetEstimator:
    """One peer's clock offset: `add` each exchange; the estimate is the least-round-trip one
    of the last `window` exchanges no older than `max_age_s` (by our clock, at the newest)."""

    def __init__(self, window: int = 64, max_age_s: float = 30.0) -> None:
        if window < 1 or not max_age_s > 0.0:
            raise ValueError(f"window {window} must be >= 1 and max_age_s {max_age_s} > 0")
        self.window, self.max_age_s = window, max_age_s
        self._exchanges: deque[Exchange] = deque(maxlen=window)
        self._best: Exchange | None = None
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
        self._exchanges.append(Exchange(((t2_s - t1_s) + (t3_s - t4_s)) / 2.0, max(rtt, 0.0),
                                        t4_s))
        self.total += 1
        newest = max(e.at_s for e in self._exchanges)
        while self._exchanges[0].at_s < newest - self.max_age_s:
            self._exchanges.popleft()
        self._best = min(self._exchanges, key=lambda e: e.rtt_s)
        return True

    def reset(self) -> None:
        """Forget every exchange (the peer restarted: its clock may be another)."""
        self._exchanges.clear()
        self._best = None
        self.total = 0

    @property
    def samples(self) -> int:
        """Exchanges in the window."""
        return len(self._exchanges)

    @property
    def best(self) -> Exchange | None:
        """The exchange the estimate is, None before the first."""
        return self._best

    @property
    def offset_s(self) -> float | None:
        """The peer's clock minus ours [s], None before the first exchange."""
        return None if self._best is None else self._best.offset_s

    @property
    def rtt_s(self) -> float | None:
        """The least round trip in the window [s], None before the first exchange."""
        return None if self._best is None else self._best.rtt_s

    @property
    def uncertainty_s(self) -> float | None:
        """Half the least round trip: a bound on the offset's error [s]; None before the
        first exchange."""
        return None if self._best is None else self._best.rtt_s / 2.0

    def to_local(self, peer_s: float) -> float:
        """Time `peer_s` of the peer's clock on ours; LookupError before the first exchange."""
        if self._best is None:
            raise LookupError("no clock offset measured yet: no exchange with the peer")
        return peer_s - self._best.offset_s
