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

import math
from collections.abc import Sequence

import numpy as np

from gcs import frames
from gcs.control.gains import GRAVITY_MPS2
from gcs.fly.delay import DelayJudge
from gcs.fly.measure import TeamSample
from gcs.fly.origins import WAITING, TeamTies
from gcs.link import VehicleProxy
from gcs.link.enums import LandedState, MavModeFlag, mode_name
from gcs.mission.autopilots import profile_for
from gcs.mission.safety import VehicleStatus, tilt_rad

_IDENTITY_Q = (1.0, 0.0, 0.0, 0.0)
#: The latest TIMESYNC round trips the preflight's delay judge reads (4 s at 2 Hz: not the
#: replies a vehicle sent late while it was still starting up).
JUDGED_ROUND_TRIPS = 8
#: SYS_STATUS onboard_control_sensors_* bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK)
PREARM_CHECK_BIT = 0x10000000
_LANDED = {LandedState.ON_GROUND: True, LandedState.IN_AIR: False, LandedState.TAKEOFF: False,
           LandedState.LANDING: False}


def team_sample(proxies: Sequence[VehicleProxy], now_s: float,
                fallback: TeamSample | None = None,
                ties: tuple[np.ndarray, np.ndarray] | None = None) -> TeamSample:
    """The team's latest telemetry (ENU/FLU), ages at `now_s`; rows with nothing received yet
    take `fallback`'s row when given (else NaN, and finite[i] is False). `ties`: (offsets (n, 3),
    rotations (n, 3, 3)) of each vehicle's local frame in the team frame (gcs.fly.origins):
    positions, velocities, attitudes and accelerations are then in the team frame."""
    n = len(proxies)
    pos = np.full((n, 3), np.nan)
    vel = np.full((n, 3), np.nan)
    q = np.tile(np.array(_IDENTITY_Q), (n, 1))
    rates = np.full((n, 3), np.nan)
    force = np.full((n, 3), np.nan)
    prx = np.full(n, -math.inf)
    arx = np.full(n, -math.inf)
    ptaken = np.full(n, -math.inf)  # when the vehicle took them (gcs.link.clock)
    ataken = np.full(n, -math.inf)
    irx = np.full(n, -math.inf)
    have_q = np.zeros(n, dtype=bool)
    for i, p in enumerate(proxies):
        lpn = p.latest("LOCAL_POSITION_NED")
        if lpn is not None:
            m = lpn.msg
            pos[i] = (m.x, m.y, m.z)
            vel[i] = (m.vx, m.vy, m.vz)
            prx[i] = lpn.rx_time_s
            ptaken[i] = p.clock.sample_time_s(m.time_boot_ms * 1e-3, lpn.rx_time_s)
        aq = p.latest("ATTITUDE_QUATERNION")
        if aq is not None:
            m = aq.msg
            quat = (m.q1, m.q2, m.q3, m.q4)
            if all(math.isfinite(x) for x in quat) and sum(x * x for x in quat) > 1e-6:
                q[i] = quat
                have_q[i] = True
            rates[i] = (m.rollspeed, m.pitchspeed, m.yawspeed)
            arx[i] = aq.rx_time_s
            ataken[i] = p.clock.sample_time_s(m.time_boot_ms * 1e-3, aq.rx_time_s)
        imu = p.latest("HIGHRES_IMU")
        if imu is not None:
            m = imu.msg
            force[i] = (m.xacc, m.yacc, m.zacc)
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
    if ties is not None:  # local ENU -> team ENU: p = o + R p_local, and R for every vector
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


def listen_label(p: VehicleProxy) -> str:
    """'udp 127.0.0.1:14540': where the ground station listens for the vehicle."""
    host, port = p.local_address
    return f"udp {host}:{port}"


def vehicle_statuses(proxies: Sequence[VehicleProxy], ids: Sequence[int], sample: TeamSample,
                     want_rates: bool, ties: TeamTies | None = None,
                     judge: DelayJudge | None = None) -> list[VehicleStatus]:
    """What the mission machine sees of each vehicle (see gcs.mission.safety.VehicleStatus);
    `ties`: the frame ties, whose problems the preflight reports; `judge`: the criterion at each
    link's measured delay (preflight only: pass it while the machine is there)."""
    out = []
    for i, p in enumerate(proxies):
        hb = p.latest("HEARTBEAT")
        armed, mode, autopilot, vtype = False, "", 0, 0
        if hb is not None:
            m = hb.msg
            armed = bool(int(m.base_mode) & MavModeFlag.SAFETY_ARMED)
            autopilot, vtype = int(m.autopilot), int(m.type)
            # the profile's names (ArduPilot BRAKE included) are the ones the mission compares
            profile = profile_for(autopilot)
            mode = (profile.mode_name(int(m.custom_mode)) if profile is not None
                    else mode_name(autopilot, int(m.custom_mode)))
        landed, landed_state = None, 0
        ess = p.latest("EXTENDED_SYS_STATE")
        if ess is not None:
            try:
                landed_state = int(LandedState(int(ess.msg.landed_state)))
                landed = _LANDED.get(LandedState(landed_state))
            except ValueError:
                landed = None
        prearm_ok = None
        sys_status = p.latest("SYS_STATUS")
        if sys_status is not None and int(sys_status.msg.onboard_control_sensors_present) \
                & PREARM_CHECK_BIT:
            prearm_ok = bool(int(sys_status.msg.onboard_control_sensors_health) & PREARM_CHECK_BIT)
        text = p.statustexts.latest()
        gpi = p.latest("GLOBAL_POSITION_INT")
        height = float(gpi.msg.relative_alt) * 1e-3 if gpi is not None else math.nan
        rates = {k: v.rate_hz for k, v in p.stats().by_type.items()} if want_rates else {}
        out.append(VehicleStatus(
            vehicle_id=ids[i], sysid=p.config.sysid, link=p.link_state().value, armed=armed,
            mode=mode, landed=landed, position_enu_m=tuple(sample.position_m[i].tolist()),
            velocity_enu_mps=tuple(sample.velocity_mps[i].tolist()),
            tilt_rad=tilt_rad(sample.rotation[i]), data_age_s=float(sample.age_s[i]),
            delay_s=float(sample.transit_s[i]),
            autopilot=autopilot, vehicle_type=vtype, sysid_mismatch=p.sysid_mismatch,
            rates_hz=rates, listen=listen_label(p), landed_state=landed_state,
            prearm_ok=prearm_ok, status_text=text.quoted() if text is not None else "",
            height_above_home_m=height,
            frame_problem=None if ties is None else ties.problems[i],
            frame_pending=ties is not None and ties.problems[i] == WAITING,
            loop_problem=(judge.refusal(autopilot, p.clock.round_trips_s()[-JUDGED_ROUND_TRIPS:])
                          if judge is not None else None),
        ))
    return out
