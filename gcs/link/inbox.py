"""What one vehicle has sent, whichever receive path stored it.

A proxy's messages arrive by two paths: the slow one decodes with pymavlink into a
`TelemetryCache` (every type, signed links, the tlog), the hot one (`gcs.link.fastpath`) stores
the fixed-layout telemetry of many vehicles in its port's table, one `HotRow` per vehicle.
`Inbox` answers for both: the newer of the two wins, counts add up.
"""

from __future__ import annotations

import math

from gcs.link.codec import MAVLinkMessage
from gcs.link.fastpath import HotRow
from gcs.link.telemetry import (
    Received,
    SequenceStats,
    SequenceTracker,
    TelemetryCache,
    TypeStats,
)


class Inbox:
    """One vehicle's accepted messages: the latest of each type, receive rates, the count and
    the sequence loss. ``hot`` is its row of the port's table, or None (no hot path)."""

    def __init__(self, hot: HotRow | None) -> None:
        self.hot = hot
        self._cache = TelemetryCache()
        self._seq = SequenceTracker()
        self._accepted = 0  # by the slow path

    def store(self, msg: MAVLinkMessage, now_s: float, *, counted: bool) -> None:
        """An accepted message from the slow path, received at ``now_s``; ``counted``: the hot
        path has already counted it (and its sequence number)."""
        if not counted:
            self._accepted += 1
            self._seq.update(msg.get_seq())
        self._cache.update(msg, now_s)

    def latest(self, kind: str) -> Received | None:
        """The latest accepted message of type ``kind`` with its receive time."""
        cached = self._cache.latest(kind)
        if self.hot is None:
            return cached
        hot = self.hot.latest(kind)
        if hot is None or (cached is not None and cached.rx_time_s > hot.rx_time_s):
            return cached
        return hot

    def last_any_rx_s(self) -> float:
        """Receive time of the latest message of any type; -inf before the first."""
        if self.hot is None:
            return self._cache.last_any_rx_s
        return max(self._cache.last_any_rx_s, self.hot.last_any_rx_s())

    def heartbeat_rx_s(self) -> float:
        """Receive time of the latest HEARTBEAT (the slow path's alone); -inf before one."""
        hb = self._cache.latest("HEARTBEAT")
        return hb.rx_time_s if hb is not None else -math.inf

    def heartbeat(self) -> Received | None:
        return self._cache.latest("HEARTBEAT")

    def accepted(self) -> int:
        """Messages accepted by both paths."""
        return self._accepted if self.hot is None else self._accepted + self.hot.accepted()

    def rate_hz(self, kind: str) -> float:
        """Receive rate of one type (EWMA of its intervals; NaN before three arrived, 0 if
        never)."""
        hot = self.hot.rate_hz(kind) if self.hot is not None else None
        return hot if hot is not None else self._cache.rate_hz(kind)

    def restart_rate(self, kind: str) -> None:
        """Measure ``kind``'s receive rate afresh (a new rate was asked for)."""
        self._cache.restart_rate(kind)
        if self.hot is not None:
            self.hot.restart_rate(kind)

    def sequence_and_types(self) -> tuple[SequenceStats, dict[str, TypeStats]]:
        """Sequence loss and per-type counts over both paths."""
        seq, by_type = self._seq.stats(), self._cache.type_stats()
        if self.hot is not None:
            seq, by_type = self.hot.sequence_stats(seq), self.hot.type_stats(by_type)
        return seq, by_type
