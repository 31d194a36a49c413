"""SupervisorBus: the supervisor's side of the bus (`gcs fly --agents`). It hears every
vehicle's state samples (the team's formation error, live) and every agent's status, and
sends the agents gates, an abort and periodic heartbeats.

    async with SupervisorBus.for_team(team) as bus:
        async with asyncio.TaskGroup() as tasks:
            tasks.create_task(bus.beat(period_s=0.1))   # heartbeats until cancelled
            await bus.wait_heard(team.ids(), timeout_s=60.0)
            bus.open_gate("formation")
            rows = bus.rows(team.ids(), time.monotonic())
            fresh = rows.fresh(bus.network.stale_after_s)
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from gcs.agent.control import (
    Abort,
    Gate,
    Heartbeat,
    OpenGate,
    Status,
    decode_control,
    encode_control,
)
from gcs.agent.session import BusSession, Clock, Keys, supervisor_endpoints, wire_shift
from gcs.agent.table import SampleTable
from gcs.agent.wire import SUPERVISOR_ID, WireError
from gcs.config.modes import FlyAction
from gcs.config.network_schema import NetworkConfig
from gcs.config.schema import TeamConfig

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)


class SupervisorBus(BusSession):
    """The supervisor's bus for a team `team_ids`. `statuses`: each vehicle's latest status;
    `status_updates`: every status in arrival order (when full, the oldest is dropped and
    counted in `statuses_dropped`); `strangers`: samples on the team's keys from no vehicle of
    it, with the last key."""

    def __init__(self, network: NetworkConfig, team_name: str, team_ids: Sequence[int], *,
                 clock: Clock = time.monotonic, system_clock: Clock = time.time,
                 epoch: int | None = None, status_queue_size: int = 4096) -> None:
        self.network = network
        self.team_ids = tuple(team_ids)
        table = SampleTable(self.team_ids, local_ids=(SUPERVISOR_ID,), team_ids=self.team_ids,
                            clocks=network.clocks, tolerance_s=network.clock_tolerance_s,
                            wire_shift=wire_shift(network.clocks, clock, system_clock))
        super().__init__(supervisor_endpoints(network, self.team_ids),
                         Keys(network.key_root(team_name)), table, clock=clock, epoch=epoch)
        self.statuses: dict[int, Status] = {}
        self.status_received_s: dict[int, float] = {}
        self.status_updates: asyncio.Queue[Status] = asyncio.Queue(status_queue_size)
        self.statuses_dropped = 0
        self.status_corrupt: dict[int, int] = dict.fromkeys(self.team_ids, 0)
        self.status_corrupt_reason: dict[int, str] = {}
        self.strangers = 0
        self.stranger_key: str | None = None
        self.gates: tuple[OpenGate, ...] = ()
        self.abort_order: Abort | None = None
        self._seq = 0
        self._pub: zenoh.Publisher | None = None

    @classmethod
    def for_team(cls, team: TeamConfig, *, clock: Clock = time.monotonic,
                 system_clock: Clock = time.time, epoch: int | None = None) -> SupervisorBus:
        return cls(team.network, team.name, team.ids(), clock=clock, system_clock=system_clock,
                   epoch=epoch)

    def _declare(self) -> None:
        self._pub = self.publisher(self.keys.supervisor, express=False)
        self.subscribe(self.keys.state("*"), self._on_state_key)
        self.subscribe(self.keys.status("*"), self._on_status_key)

    def _vehicle_of(self, key: str, template: str) -> int | None:
        """The vehicle id in `key` (matching `template` with '*' for the id); None, counted as
        a stranger, for a key of no vehicle of the team."""
        head, tail = template.split("*")
        text = key[len(head):len(key) - len(tail)] if key.startswith(head) else ""
        vid = int(text) if text.isdigit() and key.endswith(tail) else None
        if vid is None or vid not in self.table.senders:
            self.strangers += 1
            self.stranger_key = key
            return None
        return vid

    def _on_state_key(self, key: str, data: bytes, received_s: float) -> None:
        vid = self._vehicle_of(key, self.keys.state("*"))
        if vid is not None:
            self._on_state(vid, data, received_s)

    def _on_status_key(self, key: str, data: bytes, received_s: float) -> None:
        vid = self._vehicle_of(key, self.keys.status("*"))
        if vid is None:
            return
        try:
            status = decode_control(data, self.team_ids)
            if not isinstance(status, Status) or status.vehicle_id != vid:
                raise WireError(f"expected vehicle {vid}'s status, got {status!r}"[:200])
        except WireError as exc:
            self.status_corrupt[vid] += 1
            self.status_corrupt_reason[vid] = exc.reason
            return
        self.statuses[vid] = status
        self.status_received_s[vid] = received_s
        if self.status_updates.full():
            self.status_updates.get_nowait()
            self.statuses_dropped += 1
        self.status_updates.put_nowait(status)

    # ----------------------------------------------------------------------------------------
    # Sending (each returns at once).

    def _send(self, message: Heartbeat | Gate | Abort) -> None:
        if self._pub is None:
            raise RuntimeError("the bus is not open: use `async with` around it")
        data = encode_control(message)
        self._pub.put(data)
        self._count_sent(len(data))
        self._seq += 1

    def open_gate(self, name: str, at_s: float | None = None) -> Gate:
        """Open gate `name` now, or at `at_s` (both the supervisor's clock: a formation start
        agreed ahead), and tell the agents; every later heartbeat repeats it. Opening an open
        gate sends it again with its first time. `gates` and the messages hold the times on
        the wire clock (gcs/agent/table.py)."""
        opened = {g.name: g.opened_s for g in self.gates}
        if name not in opened:
            opened[name] = self.wire_s(self.clock() if at_s is None else at_s)
            self.gates = (*self.gates, OpenGate(name, opened[name]))
        gate = Gate(self._seq, self.wire_s(self.clock()), name, opened[name])
        self._send(gate)
        return gate

    def abort(self, reason: str, action: FlyAction = FlyAction.LAND) -> Abort:
        """Tell every agent to stop the formation and do `action`; later heartbeats repeat
        it. A second abort repeats the first one's reason and action."""
        if self.abort_order is None:
            self.abort_order = Abort(self._seq, self.wire_s(self.clock()), reason, action)
        order = self.abort_order
        message = Abort(self._seq, self.wire_s(self.clock()), order.reason, order.action)
        self._send(message)
        return message

    def heartbeat(self) -> Heartbeat:
        """Send one heartbeat: the open gates, the abort order, an echo of every vehicle's
        newest state sample since the last heartbeat (the agents' clock offsets to the
        supervisor, which place the formation start: a millisecond's bias there is nothing, and
        a heartbeat stays one echo per vehicle)."""
        now = self.clock()
        order = self.abort_order
        beat = Heartbeat(self._seq, self.wire_s(now), self.gates, order and order.reason,
                         order and order.action, self.table.echoes(now, SUPERVISOR_ID, 1))
        self._send(beat)
        return beat

    async def beat(self, period_s: float) -> None:
        """Send a heartbeat every `period_s` until cancelled (run it in the supervisor's
        TaskGroup); network.supervisor_lost_after_s should be several periods."""
        if not period_s > 0.0:
            raise ValueError(f"period_s must be > 0, got {period_s!r}")
        loop = asyncio.get_running_loop()
        deadline = loop.time()
        while True:
            self.heartbeat()
            deadline += period_s
            await asyncio.sleep(max(0.0, deadline - loop.time()))

    def status_age_s(self, vehicle_id: int, now_s: float) -> float:
        """Time since vehicle `vehicle_id`'s latest status arrived (inf before the first)."""
        return now_s - self.status_received_s.get(vehicle_id, -float("inf"))
