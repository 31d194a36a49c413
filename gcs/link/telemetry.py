"""Telemetry cache of one vehicle: latest message per type, receive times, rates, sequence loss."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from gcs import frames
from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import LandedState, MavModeFlag, mode_name

FloatArray = frames.FloatArray

#: Weight of the newest inter-arrival interval in the per-type rate estimate.
RATE_EWMA_ALPHA = 0.1
#: An interval enters the estimate clipped at this many times the estimate: a silence (a
#: vehicle program that stopped a few seconds, a lost burst) moves it by at most 30 %, and a
#: stream that really slowed down is followed within a few of its intervals.
RATE_CLIP = 4.0


def next_interval(old: float, dt: float) -> float:
    """The rate estimate's mean interval [s] after an interval ``dt``. ``old`` NaN: nothing
    measured yet, so this first interval (from whatever came before: a default rate, a start-up
    silence) is skipped and +inf returned; +inf: ``dt`` seeds the estimate. (Inlined in
    gcs.link.fastpath's compiled receive loop.)"""
    if old != old:
        return math.inf
    if old == math.inf:
        return dt
    return old + RATE_EWMA_ALPHA * (min(dt, RATE_CLIP * old) - old)


class Clock(Protocol):
    """Monotonic time source, injected so that tests control time."""

    def now_s(self) -> float:
        """Seconds on a monotonic clock (arbitrary origin)."""
        ...


class MonotonicClock:
    """The process's monotonic clock."""

    def now_s(self) -> float:
        return time.monotonic()


@dataclass(frozen=True, slots=True)
class Received:
    """A message and the monotonic time (s, GCS clock) at which it was received."""

    msg: MAVLinkMessage
    rx_time_s: float


@dataclass(frozen=True, slots=True)
class TypeStats:
    """Receive statistics of one message type."""

    count: int
    last_rx_s: float
    rate_hz: float  # EWMA of inter-arrival times; NaN until two messages arrived


@dataclass(frozen=True, slots=True)
class SequenceStats:
    """Loss estimate of one sender (sysid, compid) from its MAVLink sequence numbers.

    MAVLink numbers every packet of a sender in one sequence shared by all message types, so loss
    is known per sender (per link), not per message type.
    """

    received: int
    lost: int  # sum of forward gaps, less the late packets that arrived after all
    duplicates: int  # same sequence number as the previous packet
    reordered: int  # arrived behind the newest one (a backward jump of < 128)

    @property
    def loss_fraction(self) -> float:
        total = self.received + self.lost
        return self.lost / total if total else 0.0


class SequenceTracker:
    """Counts forward gaps in one sender's 8-bit sequence numbers."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._received = 0
        self._lost = 0
        self._duplicates = 0
        self._reordered = 0

    def update(self, seq: int) -> None:
        self._received += 1
        if self._last is None:
            self._last = seq
            return
        delta = (seq - self._last) % 256
        if delta == 0:
            self._duplicates += 1
        elif delta < 128:
            self._lost += delta - 1
            self._last = seq
        else:  # a late packet: it arrived after all, so it is not in the gap it was counted in
            self._reordered += 1
            self._lost = max(0, self._lost - 1)

    def stats(self) -> SequenceStats:
        return SequenceStats(self._received, self._lost, self._duplicates, self._reordered)


class TelemetryCache:
    """Latest message of each type with its receive time, and per-type counts and rates."""

    def __init__(self) -> None:
        self._latest: dict[str, Received] = {}
        self._count: dict[str, int] = {}
        self._interval_s: dict[str, float] = {}
        self._last_any_rx_s = -math.inf

    def update(self, msg: MAVLinkMessage, rx_time_s: float) -> None:
        """Store msg as the latest of its type; returns immediately."""
        kind = msg.get_type()
        prev = self._latest.get(kind)
        if prev is not None:
            self._interval_s[kind] = next_interval(self._interval_s.get(kind, math.nan),
                                                   rx_time_s - prev.rx_time_s)
        self._latest[kind] = Received(msg, rx_time_s)
        self._count[kind] = self._count.get(kind, 0) + 1
        self._last_any_rx_s = max(self._last_any_rx_s, rx_time_s)

    def latest(self, kind: str) -> Received | None:
        """Latest message of type ``kind`` (e.g. 'LOCAL_POSITION_NED') or None if never seen."""
        return self._latest.get(kind)

    @property
    def last_any_rx_s(self) -> float:
        """Receive time of the newest message of any type; -inf if none."""
        return self._last_any_rx_s

    def rate_hz(self, kind: str) -> float:
        """Receive rate of one type (NaN before three messages arrived, 0 if none did)."""
        if kind not in self._latest:
            return 0.0
        return rate_of(self._interval_s.get(kind, math.nan))

    def restart_rate(self, kind: str) -> None:
        """Measure ``kind``'s rate afresh (its stream was just asked for another rate): the
        interval from its latest message to the next one is skipped, the one after seeds."""
        self._interval_s.pop(kind, None)

    def type_stats(self) -> dict[str, TypeStats]:
        out: dict[str, TypeStats] = {}
        for kind, rec in self._latest.items():
            out[kind] = TypeStats(self._count[kind], rec.rx_time_s,
                                  rate_of(self._interval_s.get(kind, math.nan)))
        return out


def rate_of(interval_s: float) -> float:
    """Rate [Hz] of a mean interval (NaN: none measured yet)."""
    if interval_s == math.inf:
        return math.nan
    return 1.0 / interval_s if interval_s > 0.0 else math.nan


def _frozen(a: FloatArray) -> FloatArray:
    a.setflags(write=False)
    return a


_NAN3 = _frozen(np.full(3, np.nan))
_NAN33 = _frozen(np.full((3, 3), np.nan))


@dataclass(frozen=True, slots=True)
class VehicleState:
    """One vehicle's latest telemetry in the app's frames (ENU world, FLU body), SI units.

    Vectors are NaN and receive times -inf until the source message has been received; each
    group carries the GCS monotonic time at which its source message arrived.
    Sources: position/velocity <- LOCAL_POSITION_NED; rotation/omega <- the newer of
    ATTITUDE_QUATERNION and ATTITUDE; specific force <- HIGHRES_IMU; armed/mode <- HEARTBEAT;
    landed state <- EXTENDED_SYS_STATE.
    """

    sysid: int
    time_s: float  # GCS clock time of the snapshot
    position_enu_m: FloatArray
    velocity_enu_mps: FloatArray
    position_rx_s: float
    rotation_enu_flu: FloatArray  # body FLU -> world ENU, (3, 3)
    omega_flu_radps: FloatArray
    attitude_rx_s: float
    specific_force_flu_mps2: FloatArray
    imu_rx_s: float
    armed: bool
    base_mode: int
    custom_mode: int
    mode: str  # e.g. 'OFFBOARD', 'AUTO_LAND'; '' before the first HEARTBEAT
    autopilot: int
    heartbeat_rx_s: float
    landed_state: LandedState
    landed_state_rx_s: float

    @property
    def position_age_s(self) -> float:
        return self.time_s - self.position_rx_s

    @property
    def attitude_age_s(self) -> float:
        return self.time_s - self.attitude_rx_s

    @property
    def imu_age_s(self) -> float:
        return self.time_s - self.imu_rx_s

    @property
    def heartbeat_age_s(self) -> float:
        return self.time_s - self.heartbeat_rx_s

    @property
    def landed_state_age_s(self) -> float:
        return self.time_s - self.landed_state_rx_s


class LatestSource(Protocol):
    """What build_state reads: the latest message of a type (a cache, or a proxy)."""

    def latest(self, kind: str) -> Received | None:
        ...


def build_state(cache: LatestSource, sysid: int, now_s: float) -> VehicleState:
    """Snapshot of the cache converted to ENU/FLU (pure; conversions via gcs.frames)."""
    position, velocity, position_rx = _NAN3, _NAN3, -math.inf
    lpn = cache.latest("LOCAL_POSITION_NED")
    if lpn is not None:
        m = lpn.msg
        position = _frozen(frames.enu_from_ned([m.x, m.y, m.z]))
        velocity = _frozen(frames.enu_from_ned([m.vx, m.vy, m.vz]))
        position_rx = lpn.rx_time_s

    rotation, omega, attitude_rx = _NAN33, _NAN3, -math.inf
    aq, ae = cache.latest("ATTITUDE_QUATERNION"), cache.latest("ATTITUDE")
    if aq is not None and (ae is None or aq.rx_time_s >= ae.rx_time_s):
        m = aq.msg
        rotation = _frozen(frames.rotation_enu_flu_from_mavlink_quat([m.q1, m.q2, m.q3, m.q4]))
        omega = _frozen(frames.flu_from_frd([m.rollspeed, m.pitchspeed, m.yawspeed]))
        attitude_rx = aq.rx_time_s
    elif ae is not None:
        m = ae.msg
        rotation = _frozen(frames.rotation_enu_flu_from_mavlink_euler(m.roll, m.pitch, m.yaw))
        omega = _frozen(frames.flu_from_frd([m.rollspeed, m.pitchspeed, m.yawspeed]))
        attitude_rx = ae.rx_time_s

    force, imu_rx = _NAN3, -math.inf
    imu = cache.latest("HIGHRES_IMU")
    if imu is not None:
        m = imu.msg
        force = _frozen(frames.flu_from_frd([m.xacc, m.yacc, m.zacc]))
        imu_rx = imu.rx_time_s

    armed, base_mode, custom_mode, mode, autopilot, hb_rx = False, 0, 0, "", 0, -math.inf
    hb = cache.latest("HEARTBEAT")
    if hb is not None:
        m = hb.msg
        base_mode, custom_mode, autopilot = int(m.base_mode), int(m.custom_mode), int(m.autopilot)
        armed = bool(base_mode & MavModeFlag.SAFETY_ARMED)
        mode = mode_name(autopilot, custom_mode)
        hb_rx = hb.rx_time_s

    landed, landed_rx = LandedState.UNDEFINED, -math.inf
    ess = cache.latest("EXTENDED_SYS_STATE")
    if ess is not None:
        try:
            landed = LandedState(int(ess.msg.landed_state))
        except ValueError:
            landed = LandedState.UNDEFINED
        landed_rx = ess.rx_time_s

    return VehicleState(
        sysid=sysid, time_s=now_s,
        position_enu_m=position, velocity_enu_mps=velocity, position_rx_s=position_rx,
        rotation_enu_flu=rotation, omega_flu_radps=omega, attitude_rx_s=attitude_rx,
        specific_force_flu_mps2=force, imu_rx_s=imu_rx,
        armed=armed, base_mode=base_mode, custom_mode=custom_mode, mode=mode,
        autopilot=autopilot, heartbeat_rx_s=hb_rx,
        landed_state=landed, landed_state_rx_s=landed_rx,
    )
