"""SET_ATTITUDE_TARGET / SET_POSITION_TARGET_LOCAL_NED as ArduCopter reads them. Pure.

ArduCopter 4.7's GCS_MAVLINK_Copter (``handle_message_set_attitude_target`` and
``..._set_position_target_local_ned``); the result is None where ArduPilot calls
``mode_guided.init(true)`` (input not valid: a GUIDED vehicle stops).

Attitude: THROTTLE_IGNORE (64) is invalid; a quaternion that is used must be unit length within
1e-3 (of its squared norm); body rates are all three or none (then zero; with the attitude
ignored too that is a zero-rate command). GUID_OPTIONS bit 3 set: ``thrust`` is normalised thrust
(clamped -1..1, the emulator uses 0..1); clear: a climb rate, 0.5 holds, 1 climbs at
WPNAV_SPEED_UP, 0 descends at WPNAV_SPEED_DN (linear in between).

Position: frames LOCAL_NED (1), LOCAL_OFFSET_NED (7: relative to the vehicle), BODY_NED (8) and
BODY_OFFSET_NED (9) (rotated by the heading, relative to the vehicle; yaw relative); any of a
vector's ignore bits ignores the whole vector; accelerations with FORCE_SET are invalid; a used
velocity must be finite. Position (+ velocity feed-forward), velocity alone, or position alone
are flown; acceleration alone is accepted and flown as zero velocity (the emulator has no
acceleration input); nothing at all is invalid. The yaw rate is not flown; an ignored yaw keeps
the heading.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from vehicle_emulator.autopilots.ardupilot.flight import AngleTarget
from vehicle_emulator.autopilots.demand import AttitudeSetpoint, PositionTarget, RatesSetpoint
from vehicle_emulator.autopilots.setpoints import (
    ACC_IGNORE_BITS,
    FORCE_SET,
    IGNORE_ATTITUDE,
    IGNORE_PITCH_RATE,
    IGNORE_ROLL_RATE,
    IGNORE_THROTTLE,
    IGNORE_YAW_RATE,
    MAV_FRAME_BODY_NED,
    MAV_FRAME_BODY_OFFSET_NED,
    MAV_FRAME_LOCAL_NED,
    MAV_FRAME_LOCAL_OFFSET_NED,
    POS_IGNORE_BITS,
    RATE_LIMIT_RADPS,
    VEL_IGNORE_BITS,
    YAW_IGNORE,
    PositionTargetFields,
    position_target_enu,
)
from vehicle_emulator.physics import frames

__all__ = ["climb_rate_of_thrust", "guided_attitude_target", "guided_position_target"]

_FRAMES = (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED,
           MAV_FRAME_BODY_OFFSET_NED)


def climb_rate_of_thrust(thrust: float, speed_up_mps: float, speed_down_mps: float) -> float:
    """ArduCopter's climb rate [m/s, up] of a SET_ATTITUDE_TARGET thrust (GUID_OPTIONS bit 3
    clear)."""
    t = min(max(thrust, 0.0), 1.0)
    if t == 0.5:
        return 0.0
    if t > 0.5:
        return (t - 0.5) * 2.0 * speed_up_mps
    return -(0.5 - t) * 2.0 * speed_down_mps


def guided_attitude_target(
    type_mask: int,
    q_wxyz: Sequence[float],
    body_rates_frd: Sequence[float],
    thrust: float,
    use_thrust: bool,
    speed_up_mps: float,
    speed_down_mps: float,
) -> AngleTarget | None:
    """The module docstring's rules; None when ArduPilot would reject the message."""
    if type_mask & IGNORE_THROTTLE or not math.isfinite(thrust):
        return None
    ignored = [bool(type_mask & b) for b in (IGNORE_ROLL_RATE, IGNORE_PITCH_RATE,
                                               IGNORE_YAW_RATE)]
    if any(ignored) and not all(ignored):
        return None
    rates = [0.0, 0.0, 0.0] if all(ignored) else [float(r) for r in body_rates_frd]
    if not all(math.isfinite(r) for r in rates):
        return None
    rates = [min(max(r, -RATE_LIMIT_RADPS), RATE_LIMIT_RADPS) for r in rates]
    t = min(max(float(thrust), 0.0), 1.0) if use_thrust else 0.0
    if type_mask & IGNORE_ATTITUDE:
        sp: RatesSetpoint | AttitudeSetpoint = RatesSetpoint((rates[0], -rates[1], -rates[2]), t)
    else:
        q = np.asarray(q_wxyz, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(float(q @ q) - 1.0) >= 1e-3:
            return None
        r_enu_flu = frames.rotation_enu_flu_from_ned_frd(frames.rotation_from_quaternion(q))
        sp = AttitudeSetpoint(r_enu_flu, -rates[2], t)
    climb = 0.0 if use_thrust else climb_rate_of_thrust(float(thrust), speed_up_mps,
                                                          speed_down_mps)
    return AngleTarget(sp, use_thrust, climb)


def guided_position_target(
    f: PositionTargetFields,
    origin_enu_m: tuple[float, float, float],
    position_enu_m: tuple[float, float, float],
    yaw_enu_rad: float,
) -> tuple[PositionTarget | None, bool]:
    """(target in team ENU or None if invalid, whether it is a velocity target, which times out
    after GUID_TIMEOUT); ``origin_enu_m``: the vehicle's EKF origin in the team frame."""
    mask = f.type_mask
    if f.coordinate_frame not in _FRAMES:
        return None, False
    pos_ignore = any(mask & b for b in POS_IGNORE_BITS)
    vel_ignore = any(mask & b for b in VEL_IGNORE_BITS)
    acc_ignore = any(mask & b for b in ACC_IGNORE_BITS)
    if mask & FORCE_SET and not acc_ignore:
        return None, False
    body = f.coordinate_frame in (MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED)
    heading_ned = frames.yaw_ned_from_yaw_enu(yaw_enu_rad)
    c, s = math.cos(heading_ned), math.sin(heading_ned)

    def rotated(v: Sequence[float]) -> list[float]:
        x, y, z = (float(a) for a in v)
        return [c * x - s * y, s * x + c * y, z] if body else [x, y, z]

    pos = [math.nan] * 3
    if not pos_ignore:
        pos = rotated(f.position_ned_m)
        if not all(math.isfinite(x) for x in pos):
            return None, False
        if f.coordinate_frame != MAV_FRAME_LOCAL_NED:
            here = frames.local_ned_from_enu(np.array(position_enu_m), origin_enu_m)
            pos = [p + float(h) for p, h in zip(pos, here, strict=True)]
    vel = [math.nan] * 3
    if not vel_ignore:
        vel = rotated(f.velocity_ned_mps)
        if not all(math.isfinite(v) for v in vel):
            return None, False
    if pos_ignore and vel_ignore and acc_ignore:
        return None, False
    yaw_ned = math.nan
    if not mask & YAW_IGNORE:
        if not math.isfinite(f.yaw_ned_rad):
            return None, False
        yaw_ned = f.yaw_ned_rad + (heading_ned if body else 0.0)
    if pos_ignore and vel_ignore:  # acceleration only: flown as a stop
        vel = [0.0, 0.0, 0.0]
    target = position_target_enu(pos, vel, origin_enu_m, position_enu_m, yaw_ned, yaw_enu_rad)
    return target, pos_ignore
