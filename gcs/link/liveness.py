"""Is a vehicle's link alive? The link state and HEARTBEAT staleness of one proxy. Pure: every
time is an argument (the proxy's receive clock), so the judgement is testable without sockets."""

from __future__ import annotations

import logging
import math

from gcs.link.enums import LinkState

logger = logging.getLogger("gcs.link.proxy")  # the proxy's own records, as before the split

#: ProxyCounters fields this module counts.
LIVENESS_COUNTERS = ("link_lost_events", "heartbeat_stale_events")


class LinkLiveness:
    """The link of vehicle ``name``: WAITING before its first message, LOST when nothing at all
    arrived for ``link_timeout_s``, else ALIVE; HEARTBEAT stale when none came for
    ``heartbeat_timeout_s`` while the link is up. `check` is the monitor's step: it notes each
    change (counted and logged once)."""

    def __init__(self, name: str, link_timeout_s: float, heartbeat_timeout_s: float,
                 now_s: float) -> None:
        self.name = name
        self.link_timeout_s = link_timeout_s
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.state = LinkState.WAITING  # as the monitor last saw it
        #: when the monitor last saw the link come alive (HEARTBEAT staleness counts from there)
        self.alive_since_s = now_s
        self._stale = False
        self._n = dict.fromkeys(LIVENESS_COUNTERS, 0)

    def counts(self) -> dict[str, int]:
        """The counters of `LIVENESS_COUNTERS`, by name."""
        return dict(self._n)

    def restart(self, now_s: float) -> None:
        """The proxy opened at ``now_s``: staleness counts from there."""
        self.alive_since_s = now_s

    def link_state(self, now_s: float, last_any_rx_s: float) -> LinkState:
        """From the receive time of the vehicle's latest message of any kind (-inf: none yet).
        Every message counts, not HEARTBEAT alone (at 20 % loss five 1 Hz beats in a row go
        missing every ~50 min per vehicle while its telemetry streams on)."""
        if last_any_rx_s == -math.inf:
            return LinkState.WAITING
        if now_s - last_any_rx_s > self.link_timeout_s:
            return LinkState.LOST
        return LinkState.ALIVE

    def heartbeat_stale(self, now_s: float, last_any_rx_s: float,
                        heartbeat_rx_s: float) -> bool:
        """No HEARTBEAT (last at ``heartbeat_rx_s``, -inf: none) for `heartbeat_timeout_s` while
        other messages arrive. Counted from the later of the last HEARTBEAT and the link's
        coming alive (its first messages, or its return after a loss): a 1 Hz HEARTBEAT may well
        come a second after the telemetry, and a ground station that started listening long
        before must not call that silence."""
        since = max(heartbeat_rx_s, self.alive_since_s)
        return last_any_rx_s > -math.inf and now_s - since > self.heartbeat_timeout_s

    def check(self, now_s: float, last_any_rx_s: float, heartbeat_rx_s: float) -> None:
        """The monitor's step: note a change of the link state, then of HEARTBEAT staleness."""
        state = self.link_state(now_s, last_any_rx_s)
        if state != self.state:
            self._note(state, now_s)
        if (state == LinkState.ALIVE
                and self.heartbeat_stale(now_s, last_any_rx_s, heartbeat_rx_s) != self._stale):
            self._stale = not self._stale
            if self._stale:
                self._n["heartbeat_stale_events"] += 1
                logger.warning("%s: no HEARTBEAT for > %.2f s while its other messages "
                               "arrive; armed state and mode are those of the last one",
                               self.name, self.heartbeat_timeout_s)

    def _note(self, state: LinkState, now_s: float) -> None:
        if state == LinkState.LOST:
            self._n["link_lost_events"] += 1
            logger.warning("%s: link lost (no message for > %.2f s)", self.name,
                           self.link_timeout_s)
        else:
            logger.info("%s: link %s", self.name, state.value)
            if state == LinkState.ALIVE:
                self.alive_since_s = now_s
        self.state = state
