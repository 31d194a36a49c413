"""One process's Zenoh session on the agents' bus: its endpoints from the team's `network:`
section, the keys, and what both sides of the bus share (the table of state samples, the hand-off
of received bytes from Zenoh's threads to the event loop, the session's lifetime).

Zenoh runs a subscriber's callback on a thread of its own. The callback only takes the receive
time (this process's clock, as soon as it runs) and the bytes, and hands both to the event loop
with `loop.call_soon_threadsafe`; decoding and every state change happen on the loop's thread,
so the bus needs no lock.
"""

from __future__ import annotations

import abc
import asyncio
import json
import logging
import os
import time
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Self

import zenoh

from gcs.agent.control import EdgeFigures
from gcs.agent.table import Rows, SampleTable, no_shift
from gcs.agent.wire import SUPERVISOR_ID
from gcs.config.modes import ClockMode, NetworkMode
from gcs.config.network_schema import NetworkConfig

log = logging.getLogger(__name__)

Clock = Callable[[], float]


def wire_shift(clocks: ClockMode, clock: Clock = time.monotonic,
               system_clock: Clock = time.time) -> Clock:
    """What a process adds to its `clock` to stamp its messages (gcs/agent/table.py, the wire
    clock): with clocks disciplined the system clock's lead over it (CLOCK_REALTIME, which
    PTP and chrony discipline), read at each use, so that a slewed system clock is followed;
    else 0."""
    if ClockMode(clocks) is not ClockMode.DISCIPLINED:
        return no_shift
    return lambda: system_clock() - clock()
#: A subscriber's delivery on the event loop: (the sample's key, its bytes, receive time).
Deliver = Callable[[str, bytes, float], None]


class BusError(RuntimeError):
    """The bus cannot do what it was asked: the session does not open, a wait timed out."""


@dataclass(frozen=True, slots=True)
class Keys:
    """The team's Zenoh keys under `root` (`<key_prefix>/<team>`)."""

    root: str

    def state(self, vehicle_id: int | str) -> str:
        return f"{self.root}/state/{vehicle_id}"

    def status(self, vehicle_id: int | str) -> str:
        return f"{self.root}/agent/{vehicle_id}/status"

    @property
    def supervisor(self) -> str:
        return f"{self.root}/supervisor"


@dataclass(frozen=True, slots=True)
class Endpoints:
    """What one process's session listens on and connects to."""

    mode: NetworkMode
    listen: tuple[str, ...]
    connect: tuple[str, ...]
    multicast_scouting: bool


def _unique(items: Iterable[str], leave_out: Collection[str] = ()) -> tuple[str, ...]:
    return tuple(dict.fromkeys(x for x in items if x not in leave_out))


def agent_endpoints(network: NetworkConfig, team_ids: Sequence[int],
                    own_ids: Collection[int]) -> Endpoints:
    """An agent process serving vehicles `own_ids`: peer mode listens on their endpoints and
    connects to the agents of the vehicles before its first (team order), the supervisor's
    and the router; client mode connects to the router only."""
    router = () if network.router is None else (network.router,)
    if network.mode == NetworkMode.CLIENT:
        return Endpoints(network.mode, (), router, network.multicast_scouting)
    listen = _unique(e for vid in own_ids for e in network.agent_listen(vid))
    # one link per pair of processes: each connects to the agents of the vehicles before its
    # first own one (team order) and is connected to by those after (two peers opening a link
    # to each other at once over a lossy network could each drop the other's handshake)
    first = min(team_ids.index(v) for v in own_ids)
    others = [e for vid in team_ids[:first] if vid not in own_ids
              for e in network.agent_listen(vid)]
    connect = _unique([*others, *network.supervisor_listen(), *router], leave_out=listen)
    return Endpoints(network.mode, listen, connect, network.multicast_scouting)


def supervisor_endpoints(network: NetworkConfig, team_ids: Sequence[int]) -> Endpoints:
    """The supervisor: listens on its endpoints (every agent connects to it) and connects to
    the router."""
    router = () if network.router is None else (network.router,)
    if network.mode == NetworkMode.CLIENT:
        return Endpoints(network.mode, (), router, network.multicast_scouting)
    listen = network.supervisor_listen()
    return Endpoints(network.mode, listen, _unique(router, leave_out=listen),
                     network.multicast_scouting)


def zenoh_config(endpoints: Endpoints) -> zenoh.Config:
    """The session's configuration: mode, endpoints, multicast scouting (the rest Zenoh's
    defaults; a peer keeps retrying the endpoints it cannot reach yet)."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(endpoints.mode.value))
    config.insert_json5("listen/endpoints", json.dumps(list(endpoints.listen)))
    config.insert_json5("connect/endpoints", json.dumps(list(endpoints.connect)))
    config.insert_json5("scouting/multicast/enabled", json.dumps(endpoints.multicast_scouting))
    return config


def new_epoch() -> int:
    """A process's epoch: random, so that a restarted sender is told from its old self."""
    return int.from_bytes(os.urandom(4), "little")


class BusSession(abc.ABC):
    """What both sides of the bus share: the Zenoh session (`async with`: opened in a worker
    thread, returns once the subclass has declared its publishers and subscribers; exit closes
    it), the table of state samples, and their reading. `clock`: this process's monotonic
    clock, for receive and send times."""

    def __init__(self, endpoints: Endpoints, keys: Keys, table: SampleTable, *,
                 clock: Clock = time.monotonic, epoch: int | None = None) -> None:
        self.endpoints, self.keys, self.table = endpoints, keys, table
        self.clock = clock
        self.epoch = new_epoch() if epoch is None else epoch
        self.late = 0  # samples that arrived after the event loop closed (the bus closing)
        #: traffic of this process: messages and payload bytes put and received (any key)
        self.traffic = {"sent": 0, "sent_bytes": 0, "received": 0, "received_bytes": 0}
        self._session: zenoh.Session | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._entities: list[Any] = []
        self._heard = asyncio.Event()

    async def __aenter__(self) -> Self:
        self._loop = asyncio.get_running_loop()
        config = zenoh_config(self.endpoints)
        try:
            self._session = await asyncio.to_thread(zenoh.open, config)
        except zenoh.ZError as exc:
            raise BusError(f"the Zenoh session does not open ({self._where()}): "
                           f"{' '.join(str(exc).split())}") from exc
        try:
            self._declare()
        except BaseException:
            await self._close()
            raise
        log.info("bus open: %s", self._where())
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self._close()

    async def _close(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            self._entities.clear()
            await asyncio.to_thread(session.close)

    def _where(self) -> str:
        ep = self.endpoints
        return (f"{ep.mode.value} mode, listen {', '.join(ep.listen) or 'nothing'}, connect "
                f"{', '.join(ep.connect) or 'nothing'}, multicast scouting "
                f"{'on' if ep.multicast_scouting else 'off'}")

    @abc.abstractmethod
    def _declare(self) -> None:
        """Declare the side's publishers and subscribers (the session is open)."""

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise BusError("the bus is not open: use `async with` around it")
        return self._session

    def publisher(self, key: str, *, express: bool = True, reliable: bool = True,
                  priority: zenoh.Priority | None = None) -> zenoh.Publisher:
        """A publisher on `key` that never blocks the loop (congestion: the message is
        dropped; the next sample or heartbeat replaces it). `reliable` False marks its messages
        best effort: on a link that carries both (an endpoint with `mixed_rel=1`) they travel
        as datagrams, so a lost one is never resent ahead of newer ones; over TCP both kinds
        share the one ordered stream. `priority`: DATA_HIGH unless given; Zenoh numbers each
        priority's messages apart, and a best-effort message that arrives after a newer one
        of its priority from the same peer is dropped."""
        reliability = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        pub = self.session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.DROP, express=express,
            priority=zenoh.Priority.DATA_HIGH if priority is None else priority,
            reliability=reliability)
        self._entities.append(pub)
        return pub

    def reliabilities(self) -> dict[str, zenoh.Reliability]:
        """Each of this side's publishers' key and the reliability its messages carry."""
        return {str(e.key_expr): e.reliability for e in self._entities
                if isinstance(e, zenoh.Publisher)}

    def priorities(self) -> dict[str, zenoh.Priority]:
        """Each of this side's publishers' key and the priority its messages carry."""
        return {str(e.key_expr): e.priority for e in self._entities
                if isinstance(e, zenoh.Publisher)}

    def subscribe(self, key: str, deliver: Deliver) -> None:
        """Subscribe to `key` (a key expression); `deliver(key, bytes, received_s)` runs on the
        event loop for each sample."""
        loop, clock = self._loop, self.clock
        assert loop is not None

        traffic = self.traffic

        def counted(key: str, data: bytes, received_s: float) -> None:  # on the loop
            traffic["received"] += 1
            traffic["received_bytes"] += len(data)
            deliver(key, data, received_s)

        def on_sample(sample: zenoh.Sample) -> None:  # on a Zenoh thread
            received_s = clock()
            data = sample.payload.to_bytes()
            try:
                loop.call_soon_threadsafe(counted, str(sample.key_expr), data, received_s)
            except RuntimeError:  # the loop has closed: the bus is being torn down
                self.late += 1

        self._entities.append(self.session.declare_subscriber(key, on_sample))

    def wire_s(self, local_s: float) -> float:
        """Time `local_s` of this process's clock as its messages carry it (the wire clock)."""
        return local_s + self.table.wire_shift()

    def _on_state(self, vehicle_id: int, data: bytes, received_s: float) -> None:
        if self.table.receive(vehicle_id, data, received_s) is not None:
            self._heard.set()

    def _count_sent(self, size: int) -> None:
        self.traffic["sent"] += 1
        self.traffic["sent_bytes"] += size

    def peers(self) -> int:
        """How many Zenoh peers and routers this session is connected to now."""
        info = self.session.info
        return len(info.peers_zid()) + len(info.routers_zid())

    def rows(self, ids: Sequence[int], now_s: float) -> Rows:
        """The latest state of vehicles `ids` at `now_s` (this process's clock); see Rows."""
        return self.table.rows(ids, now_s)

    def offset(self, vehicle_id: int) -> float | None:
        """`vehicle_id`'s wire clock minus this process's (SUPERVISOR_ID: the supervisor's), as
        the rows use it: None before the first echo (measured) or while its clock has a problem
        (disciplined); else 0 with network.clocks disciplined or one-host."""
        return self.table.offset(vehicle_id)

    def stats(self) -> dict[int, EdgeFigures]:
        """Per vehicle heard: samples received, lost, duplicates, corrupt, restarts, offset."""
        return {vid: f for vid, f in self.table.stats().items() if vid != SUPERVISOR_ID}

    async def wait_heard(self, ids: Collection[int], timeout_s: float) -> None:
        """Return once a state sample of each of `ids` has arrived; BusError naming those not
        heard after `timeout_s`."""
        deadline = self.clock() + timeout_s
        while True:
            self._heard.clear()
            missing = [vid for vid in ids if self.table.latest(vid) is None]
            if not missing:
                return
            left = deadline - self.clock()
            try:
                async with asyncio.timeout(max(left, 0.0)):
                    await self._heard.wait()
            except TimeoutError:
                raise BusError(f"no state sample from vehicle(s) {', '.join(map(str, missing))} "
                               f"within {timeout_s:g} s ({self._where()})") from None
