"""One vehicle's outgoing messages: STATUSTEXT (chunked, rate-limited), GPS_GLOBAL_ORIGIN, reports.

``Link`` is where a vehicle's bytes go. ``NodeOutput`` is mixed into ``VehicleNode``
(vehicle.py), which owns the state it reads and writes (links, encoder, STATUSTEXT id and
rate-limit window, report schedule, counters).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

from vehicle_emulator.autopilots.demand import Severity
from vehicle_emulator.mavlink.codec import mavlink
from vehicle_emulator.physics.geodesy import geodetic_of_ned

log = logging.getLogger("vehicle_emulator.autopilots.node")  # the node's one logger

__all__ = ["Link", "NodeOutput", "REPORT_PERIOD_S"]

ORIGIN_ANNOUNCE_S = 0.1  # PX4 v1.16.0 sent GPS_GLOBAL_ORIGIN once, 0.1 s after its first HEARTBEAT
REPORT_PERIOD_S = 5.0
LIMITED_TEXT_PERIOD_S = 1.0
LIMITED_TEXT_BURST = 5
STATUSTEXT_MAX_BYTES = 200  # 4 chunks


class Link(Protocol):
    """Where a vehicle's bytes go: one UDP endpoint (server.py) or a test double."""

    name: str

    def send(self, data: bytes, addr: Any = None) -> None:
        """Queue bytes to ``addr`` (None: the link's current remote). Never blocks."""


class NodeOutput:
    """The outgoing messages of a ``VehicleNode`` (module docstring)."""

    __slots__ = ()

    def send_all(self, data: bytes) -> None:
        """Bytes to every link's current remote."""
        for link in self.links:
            link.send(data)

    def send_msg(self, msg: Any, link: Link | None = None, addr: Any = None) -> None:
        """Pack a pymavlink message; to (link, addr) or to all links."""
        data = self.encoder.pack(msg)
        if link is None:
            self.send_all(data)
        else:
            link.send(data, addr)

    def statustext(self, severity: Severity, text: str) -> None:
        """STATUSTEXT to all links, and the log. Up to 50 bytes: one message (id 0); longer
        (up to STATUSTEXT_MAX_BYTES): MAVLink 2 chunks of 50 bytes with one id != 0 and chunk_seq
        0, 1, ..., as PX4 sends "Arming denied: Resolve system health failures first". The
        personality's ending follows the text (px4: a TAB, as PX4 v1.16.0 sent every text)."""
        log.info("vehicle %d (sysid %d): %s", self.spec.vehicle_id, self.sysid, text)
        data = (text + self.personality.protocol.statustext_end).encode()[:STATUSTEXT_MAX_BYTES]
        if len(data) <= 50:
            self.send_msg(mavlink.MAVLink_statustext_message(int(severity), data, 0, 0))
            return
        self._text_id = self._text_id % 65535 + 1
        chunks = [data[k : k + 50] for k in range(0, len(data), 50)]
        if len(data) % 50 == 0:
            chunks.append(b"")  # the last chunk must end with a NUL: an empty one
        for seq, chunk in enumerate(chunks):
            msg = mavlink.MAVLink_statustext_message(int(severity), chunk, self._text_id, seq)
            self.send_msg(msg)

    def statustext_limited(self, now_s: float, severity: Severity, text: str) -> bool:
        """STATUSTEXT for rejected input: the same text at most once per
        LIMITED_TEXT_PERIOD_S and at most LIMITED_TEXT_BURST texts per period overall (hostile
        input must not become a flood of replies); the rest go into the periodic report.
        Returns whether it was sent."""
        if now_s >= self._limited_window_end_s:
            self._limited_window_end_s = now_s + LIMITED_TEXT_PERIOD_S
            self._limited_in_window = 0
            self._limited_last = {k: t for k, t in self._limited_last.items() if t > now_s - 1.0}
        last = self._limited_last.get(text)
        if (last is not None and now_s - last < LIMITED_TEXT_PERIOD_S) or (
            self._limited_in_window >= LIMITED_TEXT_BURST
        ):
            log.debug("vehicle %d: %s", self.spec.vehicle_id, text)
            return False
        self._limited_last[text] = now_s
        self._limited_in_window += 1
        self.statustext(severity, text)
        return True

    def drain_events(self, now_s: float | None = None) -> None:
        """Autopilot events -> STATUSTEXT (rate limited when ``now_s`` is given: replies to
        commands, which a flood could repeat)."""
        events, self.autopilot.events[:] = list(self.autopilot.events), []
        for severity, text in events:
            if now_s is None:
                self.statustext(severity, text)
            else:
                self.statustext_limited(now_s, severity, text)

    def origin_message(self, now_s: float) -> Any:
        """GPS_GLOBAL_ORIGIN: where this vehicle's LOCAL_POSITION_NED is zero."""
        lat, lon, alt = geodetic_of_ned(self.status.origin_ned_m[self.index],
                                        self.telemetry.origin_lla)
        return mavlink.MAVLink_gps_global_origin_message(
            int(round(float(lat) * 1e7)),
            int(round(float(lon) * 1e7)),
            int(round(float(alt) * 1e3)),
            int(now_s * 1e6),
        )

    def announce_origin(self, now_s: float) -> None:
        """GPS_GLOBAL_ORIGIN once, shortly after boot (as PX4 does when its EKF sets it)."""
        if not self._origin_announced and now_s >= ORIGIN_ANNOUNCE_S:
            self._origin_announced = True
            self.send_msg(self.origin_message(now_s))

    def report_input(self, now_s: float) -> None:
        """Every REPORT_PERIOD_S: one STATUSTEXT if rejected/clamped input grew."""
        if now_s < self._next_report_s:
            return
        self._next_report_s = now_s + REPORT_PERIOD_S
        total = self.counters.total(self.decode_rejected)
        if total > self.counters.reported_total:
            new = total - self.counters.reported_total
            self.counters.reported_total = total
            why = self.counters.last_reject_reason
            self.statustext(Severity.WARNING, f"Bad input: {new} msgs ({why})"[:50])
