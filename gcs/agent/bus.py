"""NeighbourBus: an agent process's side of the bus. It publishes its own vehicles' state
samples, hears only its vehicles' graph neighbours, reports each vehicle's status to the
supervisor and hands the supervisor's gates and abort to the agent.

    async with NeighbourBus.for_team(team, own_ids=[2]) as bus:
        await bus.wait_heard(bus.neighbour_ids, timeout_s=30.0)
        bus.publish(2, taken_s, p, v, a, q, w)           # returns at once (never blocks)
        rows = bus.rows([1, 3], now_s=time.monotonic())  # neighbours on this process's clock
        bus.publish_status(2, "formation")
        order = await bus.control.get()                  # a Gate or an Abort, each once
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Collection, Sequence
from typing import Any

import numpy as np
import zenoh

from gcs.agent.control import (
    Abort,
    Gate,
    Heartbeat,
    Status,
    decode_control,
    encode_control,
)
from gcs.agent.session import (
    BusSession,
    Clock,
    Keys,
    agent_endpoints,
    wire_shift,
)
from gcs.agent.table import SampleTable
from gcs.agent.wire import SUPERVISOR_ID, StateSample, WireError, encode
from gcs.config.network_schema import NetworkConfig
from gcs.config.schema import TeamConfig

log = logging.getLogger(__name__)

ArrayLike = Sequence[float] | np.ndarray

#: The priorities an agent's own vehicles' states take, in `own_ids` order: the data
#: priorities, highest first. Zenoh numbers each priority's best-effort messages apart and drops
#: one that arrives after a newer one of its priority from the same peer; an agent's vehicles'
#: samples leave together at every tick, so on one priority a jitter that swaps them costs the
#: first its sample (docs/agents.md, "Measured").
STATE_LANES = (zenoh.Priority.DATA_HIGH, zenoh.Priority.DATA, zenoh.Priority.DATA_LOW,
               zenoh.Priority.BACKGROUND)


def graph_neighbours(team: TeamConfig, own_ids: Collection[int]) -> frozenset[int]:
    """Every vehicle joined by a graph edge to one of `own_ids` (own ones included when they
    are neighbours of each other)."""
    out = set()
    for e in team.graph.edges:
        if e.i in own_ids:
            out.add(e.j)
        if e.j in own_ids:
            out.add(e.i)
    return frozenset(out)


class NeighbourBus(BusSession):
    """The bus of an agent process serving vehicles `own_ids` of a team `team_ids`, hearing
    `neighbour_ids` (state keys of no other vehicle are subscribed to) and the supervisor.
    `control`: the supervisor's gates (each name once, from a Gate or a heartbeat) and its
    abort (once), in arrival order; `gates`: every gate open so far -> when it opened (the
    supervisor's wire clock; `to_local(SUPERVISOR_ID, t)` converts it)."""

    def __init__(self, network: NetworkConfig, team_name: str, team_ids: Sequence[int],
                 own_ids: Collection[int], neighbour_ids: Collection[int], *,
                 clock: Clock = time.monotonic, system_clock: Clock = time.time,
                 epoch: int | None = None, control_queue_size: int = 256) -> None:
        team_ids = tuple(team_ids)
        strangers = sorted(set(own_ids) - set(team_ids) | set(neighbour_ids) - set(team_ids))
        if not own_ids or strangers:
            raise ValueError(f"own ids {sorted(own_ids)} and neighbour ids "
                             f"{sorted(neighbour_ids)} must be vehicles of the team "
                             f"{list(team_ids)} (at least one own)")
        self.network = network
        self.own_ids = tuple(sorted(own_ids))
        self.neighbour_ids = tuple(sorted(neighbour_ids))
        table = SampleTable((*self.neighbour_ids, SUPERVISOR_ID), local_ids=self.own_ids,
                            team_ids=team_ids, clocks=network.clocks,
                            tolerance_s=network.clock_tolerance_s,
                            wire_shift=wire_shift(network.clocks, clock, system_clock))
        super().__init__(agent_endpoints(network, team_ids, self.own_ids),
                         Keys(network.key_root(team_name)), table, clock=clock, epoch=epoch)
        self.team_ids = team_ids
        self.control: asyncio.Queue[Gate | Abort] = asyncio.Queue(control_queue_size)
        self.gates: dict[str, float] = {}
        self.abort_order: Abort | None = None
        self.control_corrupt = 0  # supervisor messages that were no valid message
        self.control_corrupt_reason: str | None = None
        self.control_dropped = 0  # gates or aborts that found `control` full
        self._seq = dict.fromkeys(self.own_ids, 0)
        self._status_seq = dict.fromkeys(self.own_ids, 0)
        self._state_pubs: dict[int, zenoh.Publisher] = {}
        self._status_pubs: dict[int, zenoh.Publisher] = {}

    @classmethod
    def for_team(cls, team: TeamConfig, own_ids: Collection[int], *,
                 clock: Clock = time.monotonic, system_clock: Clock = time.time,
                 epoch: int | None = None) -> NeighbourBus:
        """The bus of `own_ids` in `team`: its network section, its graph's neighbours."""
        return cls(team.network, team.name, team.ids(), own_ids,
                   graph_neighbours(team, own_ids), clock=clock, system_clock=system_clock,
                   epoch=epoch)

    def _declare(self) -> None:
        for k, vid in enumerate(self.own_ids):
            # latest sample wins: a lost state is replaced by the next, never resent; each own
            # vehicle's on a priority of its own (up to len(STATE_LANES) vehicles), so that the
            # jitter that swaps two samples sent together on the way does not drop the first
            self._state_pubs[vid] = self.publisher(self.keys.state(vid), reliable=False,
                                                   priority=STATE_LANES[k % len(STATE_LANES)])
            self._status_pubs[vid] = self.publisher(self.keys.status(vid), express=False)
        for vid in self.neighbour_ids:
            self.subscribe(self.keys.state(vid),
                           lambda _key, data, t, vid=vid: self._on_state(vid, data, t))
        self.subscribe(self.keys.supervisor, lambda _key, data, t: self._on_supervisor(data, t))

    # ----------------------------------------------------------------------------------------
    # Sending (each returns at once: a message the network cannot take now is dropped).

    def publish(self, vehicle_id: int, taken_s: float, position_enu_m: ArrayLike,
                velocity_enu_mps: ArrayLike, acceleration_enu_mps2: ArrayLike,
                attitude_wxyz: ArrayLike, omega_flu_radps: ArrayLike) -> StateSample:
        """Publish own vehicle `vehicle_id`'s state, taken at `taken_s` (this process's clock;
        the sample carries it and its send time on the wire clock, gcs/agent/table.py):
        world ENU position [m], velocity [m/s], acceleration [m/s^2], the FLU -> ENU attitude
        quaternion (w first) and the FLU body rates [rad/s]. It carries the next seq and an
        echo of every neighbour's (and the supervisor's) latest message. WireError for a value
        that is not finite; returns the sample sent."""
        self._own(vehicle_id)
        now = self.clock()
        shift = self.table.wire_shift()
        sample = StateSample(
            vehicle_id, self.epoch, self._seq[vehicle_id], float(taken_s) + shift, now + shift,
            _floats(position_enu_m, 3), _floats(velocity_enu_mps, 3),
            _floats(acceleration_enu_mps2, 3), _floats(attitude_wxyz, 4),
            _floats(omega_flu_radps, 3), self.table.echoes(now, vehicle_id))
        data = encode(sample)
        self._state_pubs[vehicle_id].put(data)
        self._count_sent(len(data))
        self._seq[vehicle_id] += 1
        return sample

    def publish_status(self, vehicle_id: int, phase: str, waiting_gate: str | None = None,
                       outcome: str | None = None, **more: Any) -> Status:
        """Publish own vehicle `vehicle_id`'s status with this process's edge figures (`more`:
        Status's other fields, e.g. exit_code, done, records); WireError for a text the
        message cannot carry (empty, over 300 characters)."""
        self._own(vehicle_id)
        status = Status(vehicle_id, self._status_seq[vehicle_id], self.wire_s(self.clock()), phase,
                        waiting_gate, outcome, tuple(self.stats().values()), **more)
        data = encode_control(status)
        self._status_pubs[vehicle_id].put(data)
        self._count_sent(len(data))
        self._status_seq[vehicle_id] += 1
        return status

    def publisher_matched(self, vehicle_id: int) -> bool:
        """Whether anyone (a neighbour's agent, the supervisor) subscribes to own vehicle
        `vehicle_id`'s state now, as Zenoh knows it."""
        self._own(vehicle_id)
        return self._state_pubs[vehicle_id].matching_status.matching

    def _own(self, vehicle_id: int) -> None:
        if vehicle_id not in self._state_pubs:
            raise ValueError(f"vehicle {vehicle_id} is not served by this bus (own ids "
                             f"{', '.join(map(str, self.own_ids))}), or the bus is not open")

    # ----------------------------------------------------------------------------------------
    # The supervisor.

    def _on_supervisor(self, data: bytes, received_s: float) -> None:
        try:
            message = decode_control(data, self.team_ids)
        except WireError as exc:
            self._control_corrupt(exc.reason)
            return
        if isinstance(message, Status):
            self._control_corrupt(f"a status of vehicle {message.vehicle_id} on the "
                                  "supervisor's key")
            return
        echoes = message.echoes if isinstance(message, Heartbeat) else ()
        self.table.heard(SUPERVISOR_ID, message.sent_s, received_s, echoes)
        if isinstance(message, Heartbeat):
            for gate in message.gates:
                self._open(Gate(message.seq, message.sent_s, gate.name, gate.opened_s))
            if message.abort_reason is not None and message.abort_action is not None:
                self._abort(Abort(message.seq, message.sent_s, message.abort_reason,
                                  message.abort_action))
        elif isinstance(message, Gate):
            self._open(message)
        else:
            self._abort(message)

    def _control_corrupt(self, reason: str) -> None:
        self.control_corrupt += 1
        self.control_corrupt_reason = reason
        log.debug("supervisor message refused: %s", reason)

    def _open(self, gate: Gate) -> None:
        if gate.name not in self.gates:
            self.gates[gate.name] = gate.opened_s
            self._hand(gate)

    def _abort(self, abort: Abort) -> None:
        if self.abort_order is None:
            self.abort_order = abort
            self._hand(abort)

    def _hand(self, order: Gate | Abort) -> None:
        try:
            self.control.put_nowait(order)
        except asyncio.QueueFull:
            self.control_dropped += 1
            log.warning("control queue full (%d): %r not handed to the agent (still in "
                        "bus.gates / bus.abort_order)", self.control.maxsize, order)

    def supervisor_age_s(self, now_s: float) -> float:
        """Time since the supervisor's latest message arrived (inf before the first)."""
        return now_s - self.table.last_heard_s(SUPERVISOR_ID)

    def supervisor_lost(self, now_s: float) -> bool:
        """Nothing from the supervisor for longer than network.supervisor_lost_after_s."""
        return self.supervisor_age_s(now_s) > self.network.supervisor_lost_after_s

    def to_local(self, vehicle_id: int, peer_s: float) -> float:
        """Time `peer_s` of `vehicle_id`'s wire clock (SUPERVISOR_ID: the supervisor's) on this
        process's clock; -inf while its offset is not known."""
        return self.table.to_local(vehicle_id, peer_s)

    def supervisor_instant(self, supervisor_s: float) -> float:
        """An instant the supervisor names on its clock (the formation start), on this
        process's clock as every agent converts it: by the median offset, which agents on
        alike paths to the supervisor share within a fraction of a millisecond where the
        bounded estimate of `to_local` differs by milliseconds (gcs/agent/clocks.py); -inf
        before the offset is known."""
        return self.table.to_local_agreed(SUPERVISOR_ID, supervisor_s)


def _floats(values: ArrayLike, n: int) -> tuple[float, ...]:
    out = tuple(float(x) for x in np.asarray(values, dtype=float).reshape(-1))
    if len(out) != n:
        raise WireError(f"expected {n} values, got {len(out)}")
    return out
