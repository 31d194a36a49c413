"""Per-vehicle proxy: telemetry cache, acknowledged commands, setpoint senders, GCS heartbeat."""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from types import TracebackType

import numpy as np
from numpy.typing import ArrayLike

from gcs.link.address import ADDRESS_COUNTERS, VehicleAddress
from gcs.link.clock import ROUND_TRIP_COUNTERS, LinkRoundTrips, VehicleClock
from gcs.link.codec import (
    CodecStats,
    MavlinkCodec,
    MAVLinkMessage,
    mavlink,
)
from gcs.link.commands import CommandStats
from gcs.link.config import VehicleLinkConfig
from gcs.link.enums import (
    LinkState,
    MavAutopilot,
    MavCmd,
    MavModeFlag,
    MavResult,
    MavState,
    MavType,
)
from gcs.link.fastpath import TABLE_NAMES, HotRow
from gcs.link.liveness import LIVENESS_COUNTERS, LinkLiveness
from gcs.link.port import MavlinkPort, PortStats
from gcs.link.setpoints import SETPOINT_COUNTERS, VehicleSetpoints
from gcs.link.statustext import StatusTextLog
from gcs.link.telemetry import (
    Clock,
    MonotonicClock,
    Received,
    SequenceStats,
    SequenceTracker,
    TelemetryCache,
    TypeStats,
    VehicleState,
    build_state,
)
from gcs.link.tlog import TlogWriter
from gcs.link.udp import Address, UdpStats
from gcs.link.vehicle_commands import MessageWaiters, VehicleCommands

logger = logging.getLogger(__name__)

FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2 forcing arm/disarm (PX4; ArduPilot disarm)
#: The golden ratio's fraction: slot k's periodic tasks run at phase k x this (mod 1).
_GOLDEN = 0.6180339887498949
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


class VehicleProxy:
    """One vehicle seen through its MAVLink link: owns the codec, the vehicle's address and two
    tasks (GCS HEARTBEAT, link monitor). Lifetime: ``async with VehicleProxy(cfg) as vehicle:``.

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
        self._tlog = tlog
        self._owns_port = port is None
        self._port = port if port is not None else MavlinkPort(
            config.local_port, local_host=config.local_host, tlog=tlog, name=self.name)
        table = self._port.table
        self._codec = MavlinkCodec(  # a slot's sequence numbers live in its port's table
            config.gcs_sysid, config.gcs_compid,
            seqs=table.out if table is not None and slot is not None else None,
            seq_row=slot if slot is not None else 0)
        if config.signing_key is not None:
            self._codec.setup_signing(config.signing_key, link_id=config.signing_link_id,
                                      allow_unsigned=config.allow_unsigned)
        self.clock = VehicleClock()  # the vehicle's clock: true sample times (gcs.link.clock)
        self._round_trips = LinkRoundTrips(self.clock)  # TIMESYNC replies, for the report
        self._slot = slot if table is not None else None
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
        self._cache = TelemetryCache()
        self._seq = SequenceTracker()
        self._n: dict[str, int] = {  # the others: setpoints, _address, _round_trips, _liveness
            f.name: 0 for f in fields(ProxyCounters)
            if f.name not in (*SETPOINT_COUNTERS, *ADDRESS_COUNTERS, *ROUND_TRIP_COUNTERS,
                              *LIVENESS_COUNTERS)}
        self.setpoints = VehicleSetpoints(self.name, config, self._codec, self._send,
                                          self._time_boot_ms)
        self.statustexts = StatusTextLog(self.name)  # every STATUSTEXT of the vehicle
        self._waiters = MessageWaiters(self.name)
        self._commands = VehicleCommands(self.name, config, self._codec, self._send,
                                         liveness=self, waiters=self._waiters,
                                         statustexts=self.statustexts, latest=self.latest)
        self._tasks: list[asyncio.Task[None]] = []
        self._t0_s = self._clock.now_s()
        self._liveness = LinkLiveness(self.name, config.link_timeout_s,
                                      config.heartbeat_timeout_s, self._t0_s)

    # --- lifetime --------------------------------------------------------------------------------

    async def __aenter__(self) -> VehicleProxy:
        """Bind the socket and start the owned tasks; returns when bound (first HEARTBEAT sent)."""
        if self._owns_port:
            await self._port.open()
        self._port.attach(self.config.sysid, self, self._slot)
        self._t0_s = self._clock.now_s()
        self._liveness.restart(self._t0_s)
        self._send_heartbeat()
        self._tasks = [
            asyncio.create_task(self._heartbeat_loop(), name=f"{self.name} heartbeat"),
            asyncio.create_task(self._monitor_loop(), name=f"{self.name} link monitor"),
        ]
        if self.config.timesync_period_s > 0.0:
            self._tasks.append(asyncio.create_task(self._timesync_loop(),
                                                   name=f"{self.name} timesync"))
        for task in self._tasks:
            task.add_done_callback(self._on_task_done)
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        """Cancel and await the owned tasks, fail pending waits, close the socket."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []
        self._waiters.close()
        self._port.detach(self.config.sysid)
        if self._owns_port:
            self._port.close()

    def _on_task_done(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            logger.error("%s: task %s failed", self.name, task.get_name(),
                         exc_info=task.exception())

    # --- state -----------------------------------------------------------------------------------

    @property
    def local_address(self) -> Address:
        return self._port.local_address

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
        if mismatch is not None or not self._port.shared or self._accepted():
            return mismatch
        unknown = self._port.unknown_sysids()
        return min(unknown) if unknown else None

    @property
    def shared_port(self) -> bool:
        """The GCS port serves other vehicles too."""
        return self._port.shared

    def latest(self, kind: str) -> Received | None:
        """Latest accepted message of type ``kind`` (e.g. 'ATTITUDE') with its receive time."""
        cached = self._cache.latest(kind)
        if self._hot is None:
            return cached
        hot = self._hot.latest(kind)
        if hot is None or (cached is not None and cached.rx_time_s > hot.rx_time_s):
            return cached
        return hot

    @property
    def slot(self) -> int | None:
        """This vehicle's row in its port's `HotTable` (None: no hot path)."""
        return self._slot

    def _last_any_rx_s(self) -> float:
        if self._hot is None:
            return self._cache.last_any_rx_s
        return max(self._cache.last_any_rx_s, self._hot.last_any_rx_s())

    # the commands' view of liveness (gcs.link.commands.Liveness)

    def now_s(self) -> float:
        return self._clock.now_s()

    def last_heard_s(self) -> float:
        """Receive time of the vehicle's latest message of any type; -inf before the first."""
        return self._last_any_rx_s()

    def up_since_s(self) -> float:
        """When this proxy's link came up."""
        return self._t0_s

    def _accepted(self) -> int:
        own = self._n["messages_accepted"]
        return own if self._hot is None else own + self._hot.accepted()

    def state(self) -> VehicleState:
        """Snapshot of the latest telemetry in ENU/FLU with receive times; returns immediately."""
        return build_state(self, self.config.sysid, self._clock.now_s())

    def round_trips_s(self) -> np.ndarray:
        """Every TIMESYNC round trip measured on this link [s], oldest first."""
        return self._round_trips.round_trips_s()

    def link_state(self) -> LinkState:
        """WAITING, ALIVE or LOST now (gcs.link.liveness.LinkLiveness.link_state)."""
        return self._liveness.link_state(self._clock.now_s(), self._last_any_rx_s())

    def heartbeat_stale(self) -> bool:
        """No HEARTBEAT for `heartbeat_timeout_s` while other messages arrive: the link is up,
        but armed state and mode are those of the last HEARTBEAT (logged when it happens;
        gcs.link.liveness.LinkLiveness.heartbeat_stale)."""
        return self._liveness.heartbeat_stale(self._clock.now_s(), self._last_any_rx_s(),
                                              self._heartbeat_rx_s())

    def _heartbeat_rx_s(self) -> float:
        hb = self._cache.latest("HEARTBEAT")
        return hb.rx_time_s if hb is not None else -math.inf

    def rate_hz(self, kind: str) -> float:
        """Receive rate of one message type (EWMA of its intervals; NaN before three arrived,
        0 if never); cheaper than `stats` for the few a check needs."""
        hot = self._hot.rate_hz(kind) if self._hot is not None else None
        return hot if hot is not None else self._cache.rate_hz(kind)

    def _restart_rate(self, kind: str) -> None:
        """Measure ``kind``'s receive rate afresh (telemetry.TelemetryCache.restart_rate)."""
        self._cache.restart_rate(kind)
        if self._hot is not None:
            self._hot.restart_rate(kind)

    def stats(self) -> LinkStats:
        """Every counter of the link; the hot path's counts (gcs.link.fastpath) included."""
        counters = (self._n | self.setpoints.counts() | self._address.counts()
                    | self._round_trips.counts() | self._liveness.counts())
        seq, by_type = self._seq.stats(), self._cache.type_stats()
        if self._hot is not None:
            counters["messages_accepted"] = self._accepted()
            seq, by_type = self._hot.sequence_stats(seq), self._hot.type_stats(by_type)
        return LinkStats(ProxyCounters(**counters), self._codec.stats(), self._port.udp_stats(),
                         self._commands.stats(), seq, by_type, self._port.stats())

    async def wait_message(self, kind: str, timeout_s: float,
                           predicate: Callable[[MAVLinkMessage], bool] | None = None) -> Received:
        """Wait for the next accepted message of type ``kind`` matching ``predicate``; returns when
        it arrives, raises TimeoutError naming the vehicle after ``timeout_s``."""
        return await self._waiters.wait(kind, timeout_s, predicate)

    async def wait_heartbeat(self, timeout_s: float) -> Received:
        """Latest HEARTBEAT if any, else wait for one (TimeoutError after timeout_s)."""
        hb = self._cache.latest("HEARTBEAT")
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
        for msg in self._codec.feed(data):
            if self._tlog is not None:
                self._tlog.write(bytes(msg.get_msgbuf()))
            src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
            if src_sys != cfg.sysid:
                self._address.foreign(msg, addr)
                continue
            if src_comp != cfg.compid:
                self._n["other_component"] += 1
                continue
            if not self._address.accepts(addr):
                continue
            if not seq_counted:  # else the hot path has counted it
                self._n["messages_accepted"] += 1
                self._seq.update(msg.get_seq())
            self._cache.update(msg, now_s)
            kind = msg.get_type()
            if kind in STAMPED_TYPES:
                self.clock.on_sample(msg.time_boot_ms * 1e-3, now_s)
            elif kind == "COMMAND_ACK":
                self._commands.on_ack(msg)
            elif kind == "STATUSTEXT":
                self.statustexts.feed(msg, now_s)
            elif kind == "TIMESYNC" and msg.tc1 != 0:
                self._on_timesync_reply(msg.ts1, now_s)
            if self._waiters:
                self._waiters.wake(msg, now_s)

    def _on_timesync_reply(self, ts1: int, now_s: float) -> None:
        """A TIMESYNC reply: its round trip, if the request was one of this port's. The vehicle's
        own requests (tc1 = 0) are not answered: the ground station does not steer its clock."""
        sent = self._port.timesync_sent_s(int(ts1))
        if sent is not None:
            self._round_trips.on_reply(sent, now_s)

    def _on_foreign(self, msg: MAVLinkMessage, addr: Address) -> None:
        """Called by a port serving only this vehicle: a valid message from another sysid."""
        self._address.foreign(msg, addr)

    def _learned_address(self, addr: Address) -> None:
        """The vehicle's address is learned: the hot path accepts its frames from there on."""
        assert self._hot is not None
        self._hot.learned(self._port.address_code(addr))

    # --- commands (gcs.link.vehicle_commands; each returns when done) --------------------------

    async def command_long(self, command: int, params: Sequence[float] = (), *,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """Send COMMAND_LONG, return the MAV_RESULT of its COMMAND_ACK (returns when done).

        The ACK is registered before sending; each of at most ``retries`` resends follows a
        ``timeout_s`` without ACK and increments ``confirmation``; raises CommandTimeoutError
        naming vehicle and command after the last (details: CommandChannel.command_long)."""
        return await self._commands.command_long(command, params, timeout_s=timeout_s,
                                                 retries=retries)

    async def command_confirmed(self, command: int, params: Sequence[float], *, want: str,
                                shows: Callable[[MAVLinkMessage], bool],
                                reported: Callable[[MAVLinkMessage | None], str],
                                timeout_s: float = 3.0, ack_timeout_s: float = 0.5,
                                retries: int = 2) -> tuple[MavResult, ...]:
        """Send COMMAND_LONG; return every MAV_RESULT read for it when the vehicle's HEARTBEAT
        shows its effect (``shows``), raise CommandRejectedError or CommandNotConfirmedError
        naming vehicle, ``want`` and what the HEARTBEAT ``reported`` otherwise (details:
        VehicleCommands.command_confirmed)."""
        return await self._commands.command_confirmed(
            command, params, want=want, shows=shows, reported=reported, timeout_s=timeout_s,
            ack_timeout_s=ack_timeout_s, retries=retries)

    async def arm(self, *, force: bool = False, check: bool = True, timeout_s: float = 0.5,
                  retries: int = 2) -> MavResult:
        """Arm (COMPONENT_ARM_DISARM 400); returns when acknowledged. ``check``: raise
        CommandRejectedError unless ACCEPTED (same for every helper below)."""
        return await self._commands.checked(MavCmd.COMPONENT_ARM_DISARM,
                                            [1.0, FORCE_MAGIC if force else 0.0], check,
                                            timeout_s, retries)

    async def disarm(self, *, force: bool = False, check: bool = True, timeout_s: float = 0.5,
                     retries: int = 2) -> MavResult:
        """Disarm (force: also in the air, param2 = 21196); returns when acknowledged."""
        return await self._commands.checked(MavCmd.COMPONENT_ARM_DISARM,
                                            [0.0, FORCE_MAGIC if force else 0.0], check,
                                            timeout_s, retries)

    async def set_mode_px4(self, main_mode: int, sub_mode: int = 0, *, check: bool = True,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """PX4 mode via DO_SET_MODE (176): param1 = CUSTOM_MODE_ENABLED (+ SAFETY_ARMED if the
        latest HEARTBEAT says armed), param2 = main mode, param3 = sub mode; returns when acked."""
        base = MavModeFlag.CUSTOM_MODE_ENABLED | (MavModeFlag.SAFETY_ARMED if self.state().armed
                                                  else 0)
        return await self._commands.checked(MavCmd.DO_SET_MODE,
                                            [float(base), main_mode, sub_mode], check,
                                            timeout_s, retries)

    async def set_mode_ardupilot(self, mode: int, *, check: bool = True, timeout_s: float = 0.5,
                                 retries: int = 2) -> MavResult:
        """ArduPilot mode number (e.g. GUIDED 4) via DO_SET_MODE; returns when acknowledged."""
        return await self._commands.checked(MavCmd.DO_SET_MODE,
                                            [float(MavModeFlag.CUSTOM_MODE_ENABLED), mode], check,
                                            timeout_s, retries)

    async def takeoff(self, altitude_m: float = math.nan, *, check: bool = True,
                      timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """NAV_TAKEOFF (22) with param7 = altitude (PX4: AMSL, NaN = MIS_TAKEOFF_ALT; ArduPilot:
        relative to home); returns when acknowledged (not when the vehicle reached it)."""
        return await self._commands.checked(
            MavCmd.NAV_TAKEOFF, [0, 0, 0, math.nan, math.nan, math.nan, altitude_m], check,
            timeout_s, retries)

    async def land(self, *, check: bool = True, timeout_s: float = 0.5,
                   retries: int = 2) -> MavResult:
        """NAV_LAND (21) here (lat/lon/yaw NaN); returns when acknowledged, not when landed."""
        return await self._commands.checked(
            MavCmd.NAV_LAND, [0, 0, 0, math.nan, math.nan, math.nan, 0], check, timeout_s,
            retries)

    async def param_read(self, name: str, timeout_s: float = 0.5, retries: int = 2) -> float:
        """One parameter's value by PARAM_REQUEST_READ (returns when its PARAM_VALUE arrives;
        ParamTimeoutError after ``retries`` resends: VehicleCommands.param_read)."""
        return await self._commands.param_read(name, timeout_s, retries)

    async def autopilot_version(self, timeout_s: float = 1.0, retries: int = 2) -> int:
        """AUTOPILOT_VERSION.flight_sw_version, asked for with REQUEST_MESSAGE; returns when it
        arrives (errors: VehicleCommands.autopilot_version)."""
        return await self._commands.autopilot_version(timeout_s, retries)

    async def set_message_interval(self, msg_id: int, rate_hz: float, *, check: bool = True,
                                   timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """SET_MESSAGE_INTERVAL (511): rate_hz > 0 sets 1e6/rate_hz us, 0 disables the stream;
        returns when acknowledged (errors: VehicleCommands.set_message_interval)."""
        result = await self._commands.set_message_interval(msg_id, rate_hz, check=check,
                                                           timeout_s=timeout_s, retries=retries)
        if result == MavResult.ACCEPTED:  # the rate asked for is measured from here on
            msg_type = mavlink.mavlink_map.get(msg_id)
            if msg_type is not None:
                self._restart_rate(msg_type.msgname)
        return result

    # --- setpoints (each returns immediately; gcs.link.setpoints) ---------------------------------

    def send_rates_thrust(self, rates_flu_radps: ArrayLike, thrust_norm: float) -> None:
        """SET_ATTITUDE_TARGET: body rates [rad/s, FLU; sent as FRD] and collective thrust
        [0..1]; returns immediately (checks, clamps, counts: `VehicleSetpoints`)."""
        self.setpoints.send_rates_thrust(rates_flu_radps, thrust_norm)

    def send_attitude_thrust(self, rotation_enu_flu: ArrayLike, thrust_norm: float) -> None:
        """SET_ATTITUDE_TARGET: attitude R_enu_flu (FLU body in the ENU world; sent as NED/FRD)
        and collective thrust [0..1]; returns immediately (details: `VehicleSetpoints`)."""
        self.setpoints.send_attitude_thrust(rotation_enu_flu, thrust_norm)

    def send_position_target(self, position_ned_m: ArrayLike, velocity_ned_mps: ArrayLike,
                             yaw_ned_rad: float,
                             acceleration_ned_mps2: ArrayLike | None = None) -> None:
        """SET_POSITION_TARGET_LOCAL_NED: position [m], velocity [m/s], yaw [rad, from north]
        and optional acceleration [m/s^2], all in the vehicle's local NED frame, as sent (not
        ENU, unlike the other setpoints); returns immediately (details: `VehicleSetpoints`)."""
        self.setpoints.send_position_target(position_ned_m, velocity_ned_mps, yaw_ned_rad,
                                            acceleration_ned_mps2)

    def send_actuator_controls(self, torque_flu_norm: ArrayLike, thrust_norm: float) -> None:
        """SET_ACTUATOR_CONTROL_TARGET: torque [-1..1, FLU; sent as FRD] and thrust [0..1];
        returns immediately (details: `VehicleSetpoints`)."""
        self.setpoints.send_actuator_controls(torque_flu_norm, thrust_norm)

    # --- what a team batch uses (setpoints.TeamSetpoints) ----------------------------------------

    @property
    def batch_sendable(self) -> bool:
        """Setpoints may be packed for the team at once (`TeamSetpoints`): an
        unsigned link."""
        return not self._codec.signing_enabled

    @property
    def codec(self) -> MavlinkCodec:
        """This link's codec (its outgoing sequence numbers, the ground station's ids)."""
        return self._codec

    @property
    def port(self) -> MavlinkPort:
        return self._port

    @property
    def tlog(self) -> TlogWriter | None:
        return self._tlog

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
        data = self._codec.encode(msg)
        if self._tlog is not None:
            self._tlog.write(data)
        remote = self._address.remote
        if remote is None:
            self._n["send_no_remote"] += 1
        return self._port.send_to(data, remote)

    @property
    def _phase(self) -> float:
        """Where in its periods this vehicle's periodic tasks run (0..1): spread by slot (golden
        ratio steps, even for any team size), so a team's hundreds of proxies do not all send
        and check in the same event-loop pass and stall the tick for milliseconds."""
        return ((self._slot or 0) * _GOLDEN) % 1.0

    async def _heartbeat_loop(self) -> None:
        loop = asyncio.get_running_loop()
        period = self.config.heartbeat_period_s
        next_s = loop.time() + (self._phase - 1.0) * period  # the first went out on opening
        while True:
            next_s = max(next_s + period, loop.time())
            await asyncio.sleep(next_s - loop.time())
            self._send_heartbeat()

    async def _timesync_loop(self) -> None:
        period = self.config.timesync_period_s
        await asyncio.sleep(self._phase * period)
        while True:
            remote = self._address.remote
            if remote is not None:
                ts1 = self._port.claim_timesync(remote, self._clock.now_s(), period)
                if ts1 is not None:
                    self._send(self._codec.mav.timesync_encode(0, ts1))
                    self._n["timesync_sent"] += 1
            await asyncio.sleep(period)

    def _send_heartbeat(self) -> None:
        self._send(self._codec.mav.heartbeat_encode(
            MavType.GCS, MavAutopilot.INVALID, 0, 0, MavState.ACTIVE))

    async def _monitor_loop(self) -> None:
        period = min(self.config.link_timeout_s, self.config.heartbeat_timeout_s) / 4.0
        await asyncio.sleep(self._phase * period)
        while True:
            self._monitor_pass()
            await asyncio.sleep(period)

    def _monitor_pass(self) -> None:
        """One look of the link monitor: notes a change of link state or HEARTBEAT staleness."""
        self._liveness.check(self._clock.now_s(), self._last_any_rx_s(), self._heartbeat_rx_s())
