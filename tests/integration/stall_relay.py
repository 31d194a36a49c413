"""A UDP relay between a ground station and one vehicle that plays a vehicle program which
stops for a while right after it was first heard (compiling, starting, paused by a loaded host).

Real sockets on 127.0.0.1. Everything passes until the vehicle's first HEARTBEAT has; then, for
`stall_s`, what the ground station sends is held (as a blocked program's socket queues it) and
what the vehicle sends is dropped (a blocked program sends nothing); then the held datagrams
are delivered in order and both directions pass again.
"""

from __future__ import annotations

import selectors
import socket
import threading
import time

from pymavlink.dialects.v20 import common as mavlink


class StallRelay:
    """``gcs_side`` is the vehicle's address for the ground station (its team file's
    remote_port); ``vehicle_side`` is the ground station's address for the vehicle (the
    emulator's team file's local_port). Stops (and closes) on exit."""

    def __init__(self, gcs_port: int, vehicle_port: int, stall_s: float) -> None:
        self.gcs = ("127.0.0.1", gcs_port)
        self.vehicle = ("127.0.0.1", vehicle_port)
        self.stall_s = stall_s
        self.stalled_at: float | None = None  # monotonic time the stall began
        self.held = self.dropped = 0
        self._gcs_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._veh_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for s in (self._gcs_sock, self._veh_sock):
            s.bind(("127.0.0.1", 0))
            s.setblocking(False)
        self.gcs_side = self._gcs_sock.getsockname()[1]
        self.vehicle_side = self._veh_sock.getsockname()[1]
        self._parser = mavlink.MAVLink(None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stall relay", daemon=True)

    def __enter__(self) -> StallRelay:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._gcs_sock.close()
        self._veh_sock.close()

    def _stalled(self, now: float) -> bool:
        return self.stalled_at is not None and now < self.stalled_at + self.stall_s

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._gcs_sock, selectors.EVENT_READ)
        sel.register(self._veh_sock, selectors.EVENT_READ)
        queue: list[bytes] = []
        while not self._stop.is_set():
            for key, _ in sel.select(timeout=0.01):
                data, _ = key.fileobj.recvfrom(65536)
                now = time.monotonic()
                if key.fileobj is self._gcs_sock:  # ground station -> vehicle
                    if self._stalled(now):
                        queue.append(data)
                        self.held += 1
                    else:
                        self._veh_sock.sendto(data, self.vehicle)
                elif self._stalled(now):
                    self.dropped += 1
                else:  # vehicle -> ground station
                    self._gcs_sock.sendto(data, self.gcs)
                    if self.stalled_at is None and self._has_heartbeat(data):
                        self.stalled_at = now
            if queue and not self._stalled(time.monotonic()):
                for data in queue:
                    self._veh_sock.sendto(data, self.vehicle)
                queue.clear()
        sel.close()

    def _has_heartbeat(self, data: bytes) -> bool:
        msgs = self._parser.parse_buffer(data) or []
        return any(m.get_msgId() == mavlink.MAVLINK_MSG_ID_HEARTBEAT for m in msgs)
