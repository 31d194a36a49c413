"""Batched team snapshot for the tick: the proxies' latest messages -> one TeamSample, and the
mission's per-vehicle `VehicleStatus`.

`VehicleProxy.state()` converts one vehicle at a time (tens of microseconds each); the tick
needs the whole team every period, so this module reads the cached messages (with their receive
times) and converts the team in one call per quantity through gcs.frames (the only place that
knows NED/FRD). Receive ages come from the receive times, delays (true ages) from each message's
time_boot_ms through the vehicle's clock filter (gcs.link.clock). Sources: LOCAL_POSITION_NED
(position, velocity), ATTITUDE_QUATERNION (attitude, body rates), HIGHRES_IMU (specific force),
HEARTBEAT (armed, mode), EXTENDED_SYS_STATE (landed).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit

from gcs import frames
from gcs.control.gains import GRAVITY_MPS2
from gcs.fly.delay import DelayJudge, TorqueDelayJudge
from gcs.fly.measure import TeamSample
from gcs.fly.origins import WAITING, TeamTies
from gcs.link import HotTable, VehicleProxy
from gcs.link.enums import LandedState, LinkState, mode_name
from gcs.link.fastpath import (
    ATTQ,
    EXTENDED_SYS_STATE,
    GLOBAL_POSITION_INT,
    IMU,
    LANDED_STATE,
    LPN,
    RELATIVE_ALT_M,
    SENSORS_HEALTH,
    SENSORS_PRESENT,
    SYS_STATUS,
    TableArrays,
)
from gcs.link.samples import (
    AttitudeQuaternion,
    ExtendedSysState,
    GlobalPosition,
    Heartbeat,
    HighresImu,
    LocalPositionNed,
    SysStatus,
)
from gcs.mission.autopilots import profile_for
from gcs.mission.safety import VehicleStatus

_IDENTITY_Q = (1.0, 0.0, 0.0, 0.0)
_EYE = np.eye(3)
#: SYS_STATUS onboard_control_sensors_* bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK)
PREARM_CHECK_BIT = 0x10000000
_LANDED = {LandedState.ON_GROUND: True, LandedState.IN_AIR: False, LandedState.TAKEOFF: False,
           LandedState.LANDING: False}
_LANDED_BY_VALUE = {int(k): v for k, v in _LANDED.items()}
_LANDED_STATES = frozenset(int(s) for s in LandedState)
_LINK_TEXT = {state: state.value for state in LinkState}  # Enum.value is a slow descriptor


class Gathered(NamedTuple):
    """The team's latest telemetry as the vehicles sent it (NED/FRD, MAVLink units), before
    `team_sample` converts it: NaN values and -inf times where nothing was received yet."""

    position_ned_m: np.ndarray  # LOCAL_POSITION_NED
    velocity_ned_mps: np.ndarray
    quat_wxyz: np.ndarray  # ATTITUDE_QUATERNION (identity until a valid one)
    rates_frd_radps: np.ndarray
    force_frd_mps2: np.ndarray  # HIGHRES_IMU's specific force
    position_rx_s: np.ndarray  # receive times [s, GCS clock]
    attitude_rx_s: np.ndarray
    position_taken_s: np.ndarray  # when the vehicle took them [s, GCS clock]
    attitude_taken_s: np.ndarray
    imu_rx_s: np.ndarray
    have_quat: np.ndarray  # a valid quaternion arrived


def team_sample(proxies: Sequence[VehicleProxy], now_s: float,
                fallback: TeamSample | None = None,
                ties: tuple[np.ndarray, np.ndarray] | None = None,
                table: HotTable | None = None) -> TeamSample:
    """The team's latest telemetry (ENU/FLU), ages at `now_s`; rows with nothing received yet
    take `fallback`'s row when given (else NaN, and finite[i] is False). `ties`: (offsets (n, 3),
    rotations (n, 3, 3)) of each vehicle's local frame in the team frame (gcs.fly.origins):
    positions, velocities, attitudes and accelerations are then in the team frame. `table`: the
    hot path's (proxy i in row i): read as arrays, message by message, the proxies' caches only
    for the messages it has nothing of yet (before a vehicle's address is learned, its messages
    take the slow path)."""
    n = len(proxies)
    raw = Gathered(
        position_ned_m=np.full((n, 3), np.nan),
        velocity_ned_mps=np.full((n, 3), np.nan),
        quat_wxyz=np.tile(np.array(_IDENTITY_Q), (n, 1)),
        rates_frd_radps=np.full((n, 3), np.nan),
        force_frd_mps2=np.full((n, 3), np.nan),
        position_rx_s=np.full(n, -math.inf),
        attitude_rx_s=np.full(n, -math.inf),
        position_taken_s=np.full(n, -math.inf),  # when the vehicle took them (gcs.link.clock)
        attitude_taken_s=np.full(n, -math.inf),
        imu_rx_s=np.full(n, -math.inf),
        have_quat=np.zeros(n, dtype=bool),
    )
    pos, vel, q, rates, force, prx, arx, ptaken, ataken, irx, have_q = raw
    if table is not None:
        need_p, need_a, need_f = _from_table(proxies, table, raw)
    else:
        need_p = need_a = need_f = range(n)
    for i in need_p:
        p = proxies[i]
        lpn = p.sample(LocalPositionNed)
        if lpn is not None:
            pos[i] = lpn.position_ned_m
            vel[i] = lpn.velocity_ned_mps
            prx[i] = lpn.rx_time_s
            ptaken[i] = p.clock.sample_time_s(lpn.time_boot_s, lpn.rx_time_s)
    for i in need_a:
        p = proxies[i]
        aq = p.sample(AttitudeQuaternion)
        if aq is not None:
            quat = aq.quaternion_wxyz
            if all(math.isfinite(x) for x in quat) and sum(x * x for x in quat) > 1e-6:
                q[i] = quat
                have_q[i] = True
            rates[i] = aq.rates_frd_radps
            arx[i] = aq.rx_time_s
            ataken[i] = p.clock.sample_time_s(aq.time_boot_s, aq.rx_time_s)
    for i in need_f:
        imu = proxies[i].sample(HighresImu)
        if imu is not None:
            force[i] = imu.specific_force_frd_mps2
            irx[i] = imu.rx_time_s
    rot = frames.rotation_enu_flu_from_mavlink_quat(q)
    rot[~have_q] = np.nan
    p_enu = frames.enu_from_ned(pos)
    v_enu = frames.enu_from_ned(vel)
    omega = frames.flu_from_frd(rates)
    f_flu = frames.flu_from_frd(force)
    acc = np.einsum("nij,nj->ni", rot, f_flu)
    acc[:, 2] -= GRAVITY_MPS2
    acc[~np.isfinite(acc).all(axis=1)] = 0.0  # no IMU yet: assume v' = 0 rather than NaN
    if ties is not None and (ties[0].any() or (ties[1] != _EYE).any()):
        # local ENU -> team ENU: p = o + R p_local, and R for every vector (skipped while every
        # tie is the identity: one origin for all, the usual emulator setup)
        offsets, turn = ties
        p_enu = offsets + np.einsum("nij,nj->ni", turn, p_enu)
        v_enu = np.einsum("nij,nj->ni", turn, v_enu)
        acc = np.einsum("nij,nj->ni", turn, acc)
        rot = np.einsum("nij,njk->nik", turn, rot)
    finite = (np.isfinite(p_enu).all(axis=1) & np.isfinite(v_enu).all(axis=1) & have_q
              & np.isfinite(omega).all(axis=1))
    if fallback is not None and not finite.all():
        bad = ~finite
        p_enu[bad], v_enu[bad], rot[bad] = (fallback.position_m[bad], fallback.velocity_mps[bad],
                                            fallback.rotation[bad])
        omega[bad], acc[bad] = fallback.omega_radps[bad], fallback.acceleration_mps2[bad]
    age = now_s - np.minimum(prx, arx)
    have = np.isfinite(prx) & np.isfinite(arx)
    with np.errstate(invalid="ignore"):  # -inf - -inf where nothing arrived yet
        delay = np.where(have, now_s - np.minimum(ptaken, ataken), np.inf)
        transit = np.where(have, np.maximum(prx - ptaken, arx - ataken), np.inf)
    return TeamSample(np.ascontiguousarray(p_enu), np.ascontiguousarray(v_enu), acc,
                      np.ascontiguousarray(rot), np.ascontiguousarray(omega), age, now_s - irx,
                      finite, delay, transit, ptaken, ataken)


def _from_table(proxies: Sequence[VehicleProxy], table: HotTable,
                raw: Gathered) -> tuple[list[int], list[int], list[int]]:
    """Fill, message by message, the rows of ``raw`` the hot table has that message of (in
    place); returns the rows it lacks LOCAL_POSITION_NED, ATTITUDE_QUATERNION, HIGHRES_IMU of (read
    from the proxies' caches). Per message, not per vehicle: a vehicle whose IMU stream is not
    on yet (the preflight asks for the streams one by one) still has its position and attitude
    read from the arrays, not decoded by pymavlink at every tick (240 vehicles: ~10 ms)."""
    need = np.empty((len(proxies), 3), dtype=np.bool_)
    _gather(_own_rows(tuple(proxies)), table.arrays, table.clock_line, raw, need)
    if not need.any():  # the usual tick: the table has every vehicle's three messages
        return [], [], []
    return tuple(np.flatnonzero(need[:, k]).tolist() for k in range(3))


@functools.lru_cache(maxsize=4)
def _own_rows(proxies: tuple[VehicleProxy, ...]) -> np.ndarray:
    """(n,) True where proxy i has row i of the table (a proxy's slot never changes; the tick
    passes the same team every time, so this is built once a flight)."""
    return np.array([p.slot == i for i, p in enumerate(proxies)], dtype=np.bool_)


@njit(cache=True)
def _gather(own: np.ndarray, table: TableArrays, clock_line: np.ndarray, raw: Gathered,
            need: np.ndarray) -> None:
    """`_from_table`'s work, row by row in one call (a numpy pass per quantity cost ~0.3 ms a
    tick at 240 vehicles, three times that beside the fleet): rows ``own`` of the hot table's
    arrays (`TableArrays`) and clock lines into ``raw``. ``need[i, k]``: row i lacks message k
    of (LOCAL_POSITION_NED, ATTITUDE_QUATERNION, HIGHRES_IMU)."""
    count, lpn, attq, imu, rx_s = table.count, table.lpn, table.attq, table.imu, table.rx
    pos, vel, q, rates, force, prx, arx, ptaken, ataken, irx, have_q = raw
    for i in range(own.shape[0]):
        line = clock_line[i]
        need[i, 0] = not (own[i] and count[i, LPN] > 0)
        need[i, 1] = not (own[i] and count[i, ATTQ] > 0)
        need[i, 2] = not (own[i] and count[i, IMU] > 0)
        if not need[i, 0]:  # LOCAL_POSITION_NED: stamp, x y z, vx vy vz (NED)
            for j in range(3):
                pos[i, j] = lpn[i, 1 + j]
                vel[i, j] = lpn[i, 4 + j]
            prx[i] = rx_s[i, LPN]
            ptaken[i] = _taken(lpn[i, 0], prx[i], line)
        if not need[i, 1]:  # ATTITUDE_QUATERNION: stamp, q1..q4, body rates (FRD)
            good = True
            norm2 = 0.0
            for j in range(4):
                x = attq[i, 1 + j]
                good = good and np.isfinite(x)
                norm2 += x * x
            good = good and norm2 > 1e-6
            if good:
                for j in range(4):
                    q[i, j] = attq[i, 1 + j]
            have_q[i] = good
            for j in range(3):
                rates[i, j] = attq[i, 5 + j]
            arx[i] = rx_s[i, ATTQ]
            ataken[i] = _taken(attq[i, 0], arx[i], line)
        if not need[i, 2]:  # HIGHRES_IMU: stamp, specific force (FRD)
            for j in range(3):
                force[i, j] = imu[i, 1 + j]
            irx[i] = rx_s[i, IMU]


@njit(cache=True)
def _taken(stamp: float, rx: float, line: np.ndarray) -> float:
    """When the vehicle took a sample, on the GCS clock: its stamp through the clock filter's
    line (a, b, t_ref, least delay), never after it arrived; the receive time where the filter
    has no line yet or the stamp is not a number. NaN in, NaN out, as numpy's minimum."""
    a, b, t_ref, least = line[0], line[1], line[2], line[3]
    if not (np.isfinite(a) and np.isfinite(stamp)):
        return rx
    t = stamp + a + b * (stamp - t_ref) - least
    if np.isnan(t) or np.isnan(rx):
        return np.nan
    return min(rx, t)


def warm_up() -> None:
    """Compile (or load from numba's cache) the team sample's kernel before a flight."""
    table = HotTable(1)
    n1 = np.zeros((1, 3))
    raw = Gathered(n1, n1.copy(), np.zeros((1, 4)), n1.copy(), n1.copy(), np.zeros(1),
                   np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1, dtype=np.bool_))
    _gather(np.zeros(1, dtype=np.bool_), table.arrays, table.clock_line, raw,
            np.empty((1, 3), dtype=np.bool_))


@functools.lru_cache(maxsize=256)
def _mode_text(autopilot: int, custom_mode: int) -> str:
    """The profile's name of a mode (ArduPilot BRAKE included: the names the mission compares)."""
    profile = profile_for(autopilot)
    return (profile.mode_name(custom_mode) if profile is not None
            else mode_name(autopilot, custom_mode))


def listen_label(p: VehicleProxy) -> str:
    """'udp 127.0.0.1:14540': where the ground station listens for the vehicle."""
    return _listen_text(p.local_address)


@functools.lru_cache(maxsize=1024)
def _listen_text(address: tuple[str, int]) -> str:
    return f"udp {address[0]}:{address[1]}"


def vehicle_statuses(proxies: Sequence[VehicleProxy], ids: Sequence[int], sample: TeamSample,
                     want_rates: Sequence[str], ties: TeamTies | None = None,
                     judge: DelayJudge | TorqueDelayJudge | None = None,
                     table: HotTable | None = None,
                     rows: Sequence[int] | None = None) -> list[VehicleStatus]:
    """What the mission machine sees of each vehicle (see gcs.mission.safety.VehicleStatus);
    `want_rates`: the message types whose receive rates it checks now (none: not measured);
    `ties`: the frame ties, whose problems the preflight reports; `judge`: the criterion at each
    link's measured delay (preflight only: pass it while the machine is there); `table`: the hot
    path's (proxy i in row i), whose decoded fields stand for the lazy messages' decode;
    `rows`: only these vehicles' (in that order; default all)."""
    out = []
    which = range(len(proxies)) if rows is None else rows
    pick = np.fromiter(which, dtype=np.intp, count=len(which))
    # the rows' values as Python floats at once (a conversion per vehicle costs more; the rest of
    # the team's rows not at all: a slice of 48 of 240 vehicles converts 48)
    position, velocity = sample.position_m[pick].tolist(), sample.velocity_mps[pick].tolist()
    age, transit = sample.age_s[pick].tolist(), sample.transit_s[pick].tolist()
    with np.errstate(invalid="ignore"):
        tilt = np.arccos(np.clip(sample.rotation[pick, 2, 2], -1.0, 1.0)).tolist()
    misc = table.misc[pick].tolist() if table is not None else None
    have = (table.count[pick] > 0).tolist() if table is not None else None
    problems = ties.problems if ties is not None else None
    for j, i in enumerate(which):
        p = proxies[i]
        hb = p.sample(Heartbeat)
        armed, mode, autopilot, vtype = False, "", 0, 0
        if hb is not None:
            armed, autopilot, vtype = hb.armed, hb.autopilot, hb.vehicle_type
            mode = _mode_text(autopilot, hb.custom_mode)
        fields, got = (misc[j], have[j]) if misc is not None and have is not None and \
            p.slot == i else (None, None)
        landed_raw: int | None = None
        if got is not None and got[EXTENDED_SYS_STATE]:
            landed_raw = int(fields[LANDED_STATE])
        elif (ess := p.sample(ExtendedSysState)) is not None:
            landed_raw = ess.landed_state
        landed, landed_state = None, 0
        if landed_raw is not None:
            landed_state = landed_raw if landed_raw in _LANDED_STATES else 0
            landed = _LANDED_BY_VALUE.get(landed_raw)
        sensors: tuple[int, int] | None = None
        if got is not None and got[SYS_STATUS]:
            sensors = (int(fields[SENSORS_PRESENT]), int(fields[SENSORS_HEALTH]))
        elif (sys_status := p.sample(SysStatus)) is not None:
            sensors = (sys_status.sensors_present, sys_status.sensors_health)
        prearm_ok = None
        if sensors is not None and sensors[0] & PREARM_CHECK_BIT:
            prearm_ok = bool(sensors[1] & PREARM_CHECK_BIT)
        text = p.statustexts.latest()
        height = math.nan
        if got is not None and got[GLOBAL_POSITION_INT]:
            height = fields[RELATIVE_ALT_M]
        elif (gpi := p.sample(GlobalPosition)) is not None:
            height = gpi.height_above_home_m
        problem = problems[i] if problems is not None else None
        out.append(VehicleStatus(
            vehicle_id=ids[i], sysid=p.config.sysid, link=_LINK_TEXT[p.link_state()],
            armed=armed, mode=mode, landed=landed, position_enu_m=tuple(position[j]),
            velocity_enu_mps=tuple(velocity[j]), tilt_rad=tilt[j], data_age_s=age[j],
            delay_s=transit[j], round_trip_s=p.clock.recent_round_trip_s,
            autopilot=autopilot, vehicle_type=vtype,
            sysid_mismatch=p.sysid_mismatch,
            rates_hz={k: p.rate_hz(k) for k in want_rates} if want_rates else {},
            listen=listen_label(p), landed_state=landed_state, prearm_ok=prearm_ok,
            status_text=text.quoted() if text is not None else "", height_above_home_m=height,
            frame_problem=problem, frame_pending=problem == WAITING,
            loop_problem=judge.deferred(autopilot, p.clock, i) if judge is not None else None,
        ))
    return out


#: Teams larger than this build the mission's statuses a slice per tick (a status costs ~8 us of
#: Python per vehicle: at 240 vehicles, all at once is a 2-4 ms spike at every check).
STATUS_SLICED_ABOVE = 32


class StatusSlices:
    """Which vehicles' statuses a tick builds, and the team's latest ones for the check.

    The mission machine checks the team every ``every`` ticks. A team of at most
    `STATUS_SLICED_ABOVE` vehicles is built whole at the check. A larger one is built a slice
    per tick (vehicles j, j + every, ... at tick j mod every), so the check sees each vehicle as
    of at most every - 1 ticks before it (40 ms at 100 Hz, checks at 20 Hz), and the cost is the
    same at every tick instead of a spike; the first check builds everyone.
    """

    def __init__(self, n: int, every: int) -> None:
        self.every = every
        self._latest: list[VehicleStatus | None] = [None] * n
        self._missing = n
        self._slices = ([list(range(j, n, every)) for j in range(every)]
                        if n > STATUS_SLICED_ABOVE and every > 1 else None)

    def due(self, k: int) -> bool:
        """Tick k is a check."""
        return k % self.every == 0

    def rows(self, k: int) -> list[int] | None:
        """The vehicles tick k builds (None: all of them; []: none)."""
        if self.due(k) and self._missing:
            return None
        if self._slices is None:
            return None if self.due(k) else []
        return self._slices[k % self.every]

    def store(self, rows: list[int] | None, built: Sequence[VehicleStatus]) -> None:
        for i, status in zip(range(len(self._latest)) if rows is None else rows, built,
                             strict=True):
            if self._latest[i] is None:
                self._missing -= 1
            self._latest[i] = status

    def latest(self) -> list[VehicleStatus]:
        """Every vehicle's latest status (after the first check's build)."""
        assert not self._missing, "a check before every vehicle's status was built"
        return [s for s in self._latest if s is not None]

