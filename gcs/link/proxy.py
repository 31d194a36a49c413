"""Per-vehicle proxy: telemetry cache, acknowledged commands, setpoint senders, GCS heartbeat."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, fields
from types import TracebackType

import numpy as np

from gcs.link.address import ADDRESS_COUNTERS, VehicleAddress
from gcs.link.clock import ROUND_TRIP_COUNTERS, LinkRoundTrips, VehicleClock
from gcs.link.codec import (
    CodecStats,
    MavlinkCodec,
    MAVLinkMessage,
)
from gcs.link.commands import CommandStats
from gcs.link.config import VehicleLinkConfig
from gcs.link.duties import LinkDuties, slot_phase
from gcs.link.enums import (
    LinkState,
    MavAutopilot,
    MavState,
    MavType,
)
from gcs.link.fastpath import TABLE_NAMES, HotRow, HotTable
from gcs.link.inbox import Inbox
from gcs.link.liveness import LIVENESS_COUNTERS, LinkLiveness
from gcs.link.port import MavlinkPort, PortStats
from gcs.link.samples import S
from gcs.link.setpoints import SETPOINT_COUNTERS, VehicleSetpoints
from gcs.link.statustext import StatusTextLog
from gcs.link.telemetry import (
    Clock,
    MonotonicClock,
    Received,
    SequenceStats,
    TypeStats,
    VehicleState,
    build_state,
)
from gcs.link.tlog import TlogWriter
from gcs.link.udp import Address, UdpStats
from gcs.link.vehicle_commands import MessageWaiters, VehicleCommands

logger = logging.getLogger(__name__)

#: Messages whose time_boot_ms stamps the sample they carry (the clock filter's input).
STAMPED_TYPES = frozenset({"LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ATTITUDE"})


@dataclass(frozen=True, slots=True)
class ProxyCounters:
    """Proxy-level counters (codec, socket and sequence statistics are separate)."""

    messages_accepted: int = 0
    foreign_sysid: int = 0  # valid messages from another sysid (ignored)
    other_component: int = 0  # valid messages from our sysid, another compid (ignored)
    stranger_address: int = 0  # our sysid/compid from an address other than the learned one
    send_no_remote: int = 0  # packets not sent: the vehicle's address is not known yet
    setpoints_sent: int = 0
    setpoints_rejected: int = 0  # NaN/inf/shape errors (raised)
    thrust_clamped: int = 0  # thrust outside 0..1, clamped
    torque_clamped: int = 0  # actuator torque outside -1..1, clamped
    link_lost_events: int = 0
    heartbeat_stale_events: int = 0  # HEARTBEAT silent for heartbeat_timeout_s, link up
    timesync_sent: int = 0  # TIMESYNC requests this proxy sent
    timesync_replies: int = 0  # replies (to any request on its port) timed into the clock
    timesync_bunched: int = 0  # replies held and released together (left out: not the link)


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Everything counted on one vehicle link."""

    proxy: ProxyCounters
    codec: CodecStats
    udp: UdpStats
    commands: CommandStats
    sequence: SequenceStats
    by_type: dict[str, TypeStats]
    port: PortStats  # the GCS port's routing (shared by every vehicle on that port)


def _codec(config: VehicleLinkConfig, table: HotTable | None, slot: int | None) -> MavlinkCodec:
    """The link's codec; a slot's outgoing sequence numbers live in its port's table."""
    codec = MavlinkCodec(config.gcs_sysid, config.gcs_compid,
                         seqs=table.out if table is not None and slot is not None else None,
                         seq_row=slot if slot is not None else 0)
    if config.signing_key is not None:
        codec.setup_signing(config.signing_key, link_id=config.signing_link_id,
                            allow_unsigned=config.allow_unsigned)
    return codec


class VehicleProxy:
    """One vehicle seen through its MAVLink link: owns the codec, the vehicle's address, what it
    sent (`Inbox`), what it is asked (``commands``: `VehicleCommands`), its setpoints
    (``setpoints``: `VehicleSetpoints`) and the periodic duties (GCS HEARTBEAT, TIMESYNC, link
    monitor: `LinkDuties`). Lifetime: ``async with VehicleProxy(cfg) as vehicle:``.

    The GCS port is the proxy's own (``port=None``: bound on enter, closed on exit) or a
    `MavlinkPort` shared with other vehicles (opened and closed by its owner), which routes this
    vehicle's sysid to it. Only messages from ``config.sysid``/``config.compid`` update the cache
    and count as liveness; others are counted and ignored, and on its own port a vehicle
    HEARTBEAT with another sysid is reported as a sysid mismatch. With ``learn_remote`` the
    vehicle's address is the source of its first valid message (MAVProxy's ``udpin``); after that,
    messages with its ids from any other address are counted (``stranger_address``), logged and
    ignored. A fixed remote accepts the vehicle's messages from any address. Receive times come
    from the injected ``clock``; ack timeouts use the event loop's clock.
    """

    def __init__(self, config: VehicleLinkConfig, *, clock: Clock | None = None,
                 tlog: TlogWriter | None = None, port: MavlinkPort | None = None,
                 slot: int | None = None) -> None:
        self.config = config
        self.name = config.name
        self._clock: Clock = clock if clock is not None else MonotonicClock()
        self.tlog = tlog  # every packet sent and accepted, if given
        self._owns_port = port is None
        self.port = port if port is not None else MavlinkPort(
            config.local_port, local_host=config.local_host, tlog=tlog, name=self.name)
        table = self.port.table
        self._slot = slot if table is not None else None
        self.codec = _codec(config, table, self._slot)  # its sequence numbers, our ids
        self.clock = VehicleClock()  # the vehicle's clock: true sample times (gcs.link.clock)
        self._round_trips = LinkRoundTrips(self.clock)  # TIMESYNC replies, for the report
        # the hot path (gcs.link.fastpath): this vehicle's row in its port's table, if it has one
        self._hot: HotRow | None = None
        if table is not None and slot is not None:
            signed = config.signing_key is not None  # the codec checks signatures: no hot path
            self._hot = HotRow(table, slot, compid=-1 if signed else config.compid,
                               learn_remote=config.learn_remote)
            self.clock.bind_line(table.clock_line[slot])
        self._address = VehicleAddress(  # a learned address goes into the hot path's row too
            self.name, config.sysid, config.remote, learn_remote=config.learn_remote,
            on_learn=self._learned_address if self._hot is not None else None)
        self._inbox = Inbox(self._hot)  # what the vehicle sent, by either receive path
        self._n: dict[str, int] = {  # the others: setpoints, _address, _round_trips, _liveness
            f.name: 0 for f in fields(ProxyCounters)
            if f.name not in (*SETPOINT_COUNTERS, *ADDRESS_COUNTERS, *ROUND_TRIP_COUNTERS,
                              *LIVENESS_COUNTERS, "messages_accepted")}
        # setpoints in ENU/FLU, each sent at once (gcs.link.setpoints)
        self.setpoints = VehicleSetpoints(self.name, config, self.codec, self._send,
                                          self._time_boot_ms)
        self.statustexts = StatusTextLog(self.name)  # every STATUSTEXT of the vehicle
        self._waiters = MessageWaiters(self.name)
        # what the vehicle is asked and awaited: arm, modes, params, streams (returns when done)
        self.commands = VehicleCommands(self.name, config, self.codec, self._send,
                                        liveness=self, waiters=self._waiters,
                                        statustexts=self.statustexts, latest=self.latest,
                                        on_stream_set=self._inbox.restart_rate)
        self._t0_s = self._clock.now_s()
        self._liveness = LinkLiveness(self.name, config.link_timeout_s,
                                      config.heartbeat_timeout_s, self._t0_s)
        self._duties = LinkDuties(
            self.name, phase=slot_phase(self._slot), heartbeat=self._send_heartbeat,
            heartbeat_period_s=config.heartbeat_period_s, timesync=self._request_timesync,
            timesync_period_s=config.timesync_period_s, check=self._monitor_pass,
            check_period_s=min(config.link_timeout_s, config.heartbeat_timeout_s) / 4.0)

    # --- lifetime --------------------------------------------------------------------------------

    async def __aenter__(self) -> VehicleProxy:
        """Bind the socket and start the owned tasks; returns when bound (first HEARTBEAT sent)."""
        if self._owns_port:
            await self.port.open()
        self.port.attach(self.config.sysid, self, self._slot)
        self._t0_s = self._clock.now_s()
        self._liveness.restart(self._t0_s)
        self._duties.start()
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        """Cancel and await the owned tasks, fail pending waits, close the socket."""
        await self._duties.stop()
        self._waiters.close()
        self.port.detach(self.config.sysid)
        if self._owns_port:
            self.port.close()

    # --- state -----------------------------------------------------------------------------------

    @property
    def local_address(self) -> Address:
        return self.port.local_address

    @property
    def remote(self) -> Address | None:
        """Where commands and setpoints go: the configured address, or the learned one (None
        until the vehicle's first valid message on a link without a configured one)."""
        return self._address.remote

    @property
    def remote_learned(self) -> bool:
        return self._address.learned

    @property
    def sysid_mismatch(self) -> int | None:
        """Another vehicle's sysid heard where this one was expected: on its own port, a
        HEARTBEAT of another vehicle (preflight refuses); on a shared port, while nothing of this
        vehicle has arrived, a sysid no vehicle of the port has (for the connect diagnostics)."""
        mismatch = self._address.mismatch
        if mismatch is not None or not self.port.shared or self._inbox.accepted():
            return mismatch
        unknown = self.port.unknown_sysids()
        return min(unknown) if unknown else None

    def latest(self, kind: str) -> Received | None:
        """Latest accepted message of type ``kind`` (pymavlink's; above the link: `sample`)."""
        return self._inbox.latest(kind)

    def sample(self, kind: type[S]) -> S | None:
        """The latest accepted ``kind.MESSAGE`` as a typed sample (gcs.link.samples)."""
        got = self._inbox.latest(kind.MESSAGE)
        return None if got is None else kind.from_message(got.msg, got.rx_time_s)

    @property
    def slot(self) -> int | None:
        """This vehicle's row in its port's `HotTable` (None: no hot path)."""
        return self._slot

    # the commands' view of liveness (gcs.link.commands.Liveness)

    def now_s(self) -> float:
        return self._clock.now_s()

    def last_heard_s(self) -> float:
        """Receive time of the vehicle's latest message of any type; -inf before the first."""
        return self._inbox.last_any_rx_s()

    def up_since_s(self) -> float:
        """When this proxy's link came up."""
        return self._t0_s

    def state(self) -> VehicleState:
        """Snapshot of the latest telemetry in ENU/FLU with receive times; returns immediately."""
        return build_state(self, self.config.sysid, self._clock.now_s())

    def round_trips_s(self) -> np.ndarray:
        """Every TIMESYNC round trip measured on this link [s], oldest first."""
        return self._round_trips.round_trips_s()

    def link_state(self) -> LinkState:
        """WAITING, ALIVE or LOST now (gcs.link.liveness.LinkLiveness.link_state)."""
        return self._liveness.link_state(self._clock.now_s(), self._inbox.last_any_rx_s())

    def heartbeat_stale(self) -> bool:
        """No HEARTBEAT for `heartbeat_timeout_s` while other messages arrive: the link is up,
        but armed state and mode are those of the last HEARTBEAT (logged when it happens;
        gcs.link.liveness.LinkLiveness.heartbeat_stale)."""
        return self._liveness.heartbeat_stale(self._clock.now_s(), self._inbox.last_any_rx_s(),
                                              self._inbox.heartbeat_rx_s())

    def rate_hz(self, kind: str) -> float:
        """Receive rate of one message type (EWMA of its intervals; NaN before three arrived,
        0 if never); cheaper than `stats` for the few a check needs."""
        return self._inbox.rate_hz(kind)

    def stats(self) -> LinkStats:
        """Every counter of the link; the hot path's counts (gcs.link.fastpath) included."""
        counters = (self._n | self.setpoints.counts() | self._address.counts()
                    | self._round_trips.counts() | self._liveness.counts())
        counters["messages_accepted"] = self._inbox.accepted()
        seq, by_type = self._inbox.sequence_and_types()
        return LinkStats(ProxyCounters(**counters), self.codec.stats(), self.port.udp_stats(),
                         self.commands.stats(), seq, by_type, self.port.stats())

    async def wait_message(self, kind: str, timeout_s: float,
                           predicate: Callable[[MAVLinkMessage], bool] | None = None) -> Received:
        """Wait for the next accepted message of type ``kind`` matching ``predicate``; returns when
        it arrives, raises TimeoutError naming the vehicle after ``timeout_s``."""
        return await self._waiters.wait(kind, timeout_s, predicate)

    async def wait_heartbeat(self, timeout_s: float) -> Received:
        """Latest HEARTBEAT if any, else wait for one (TimeoutError after timeout_s)."""
        hb = self._inbox.heartbeat()
        return hb if hb is not None else await self.wait_message("HEARTBEAT", timeout_s)

    # --- receive path ----------------------------------------------------------------------------

    @property
    def hot_waiting(self) -> bool:
        """A command waits for a message the hot table holds (the port then tells at every
        batch). A wait for another message (a HEARTBEAT with the new mode, a PARAM_VALUE) comes
        through the slow path: 240 vehicles confirming their mode made every batch tell every
        vehicle, a burst of tens of milliseconds at the formation's start."""
        return self._waiters.wants_any(TABLE_NAMES)

    def _on_hot(self) -> None:
        """The port's hot path stored new messages of this vehicle: feed the clock filter the
        batch's least-delayed and newest stamps (in time order), wake waiters for them."""
        assert self._hot is not None
        self._hot.feed_clock(self.clock.on_sample)
        if self._waiters:
            for kind in TABLE_NAMES:
                if self._waiters.wants(kind):
                    got = self._hot.latest(kind)
                    if got is not None:
                        self._waiters.wake(got.msg, got.rx_time_s)

    def _on_datagram(self, data: bytes, addr: Address, seq_counted: bool = False,
                     rx_s: float | None = None) -> None:
        now_s = self._clock.now_s() if rx_s is None else rx_s
        cfg = self.config
        for msg in self.codec.feed(data):
            if self.tlog is not None:
                self.tlog.write(bytes(msg.get_msgbuf()))
            src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
            if src_sys != cfg.sysid:
                self._address.foreign(msg, addr)
                continue
            if src_comp != cfg.compid:
                self._n["other_component"] += 1
                continue
            if not self._address.accepts(addr):
                continue
            self._inbox.store(msg, now_s, counted=seq_counted)
            kind = msg.get_type()
            if kind in STAMPED_TYPES:
                self.clock.on_sample(msg.time_boot_ms * 1e-3, now_s)
            elif kind == "COMMAND_ACK":
                self.commands.on_ack(msg)
            elif kind == "STATUSTEXT":
                self.statustexts.feed(msg, now_s)
            elif kind == "TIMESYNC" and msg.tc1 != 0:  # a reply; requests are not answered
                sent = self.port.timesync_sent_s(int(msg.ts1))  # None: not this port's request
                if sent is not None:
                    self._round_trips.on_reply(sent, now_s)
            if self._waiters:
                self._waiters.wake(msg, now_s)

    def _on_foreign(self, msg: MAVLinkMessage, addr: Address) -> None:
        """Called by a port serving only this vehicle: a valid message from another sysid."""
        self._address.foreign(msg, addr)

    def _learned_address(self, addr: Address) -> None:
        """The vehicle's address is learned: the hot path accepts its frames from there on."""
        assert self._hot is not None
        self._hot.learned(self.port.address_code(addr))

    # --- what a team batch uses (setpoints.TeamSetpoints) ----------------------------------------

    @property
    def batch_sendable(self) -> bool:
        """Setpoints may be packed for the team at once (`TeamSetpoints`): an
        unsigned link."""
        return not self.codec.signing_enabled

    def batch_address(self) -> Address | None:
        """Where a packet sent for this vehicle outside `_send` goes now (a learned address may
        change); None, not known yet, is counted as ``send_no_remote`` (the port drops it)."""
        remote = self._address.remote
        if remote is None:
            self._n["send_no_remote"] += 1
        return remote

    # --- send path and owned tasks ---------------------------------------------------------------

    def _time_boot_ms(self) -> int:
        return int((self._clock.now_s() - self._t0_s) * 1000.0) & 0xFFFFFFFF

    def _send(self, msg: MAVLinkMessage) -> bool:
        data = self.codec.encode(msg)
        if self.tlog is not None:
            self.tlog.write(data)
        remote = self._address.remote
        if remote is None:
            self._n["send_no_remote"] += 1
        return self.port.send_to(data, remote)

    def _request_timesync(self) -> None:
        """Ask for a round trip, unless the vehicle's address is unknown or another proxy of the
        port timed that address within the period (`MavlinkPort.claim_timesync`)."""
        remote = self._address.remote
        if remote is not None:
            ts1 = self.port.claim_timesync(remote, self._clock.now_s(),
                                            self.config.timesync_period_s)
            if ts1 is not None:
                self._send(self.codec.mav.timesync_encode(0, ts1))
                self._n["timesync_sent"] += 1

    def _send_heartbeat(self) -> None:
        self._send(self.codec.mav.heartbeat_encode(
            MavType.GCS, MavAutopilot.INVALID, 0, 0, MavState.ACTIVE))

    def _monitor_pass(self) -> None:
        """One look of the link monitor: notes a change of link state or HEARTBEAT staleness."""
        self._liveness.check(self._clock.now_s(), self._inbox.last_any_rx_s(),
                             self._inbox.heartbeat_rx_s())
