"""SET_ATTITUDE_TARGET / SET_ACTUATOR_CONTROL_TARGET / SET_POSITION_TARGET_LOCAL_NED fields ->
checked offboard setpoints, as PX4 reads them. Pure.

PX4's type_mask rules (docs/emulator.md): bits set = ignore (1 roll rate, 2 pitch rate, 4 yaw rate,
64 throttle, 128 attitude; 32 = use thrust_body). If bit 128 is clear the quaternion is the
setpoint (attitude wins) and a non-ignored yaw rate is a feed-forward; else body rates are used
only if roll AND pitch rates are both not ignored (an ignored yaw rate then means 0). Otherwise
the message carries no setpoint and is ignored (it does not feed the offboard stream).

SET_POSITION_TARGET_LOCAL_NED (PX4 v1.14+ ``handle_message_set_position_target_local_ned``):
MAV_FRAME_LOCAL_NED: each x/y/z, vx/vy/vz, afx/afy/afz not ignored by its bit (1, 2, 4 / 8, 16,
32 / 64, 128, 256) is used (a NaN value counts as not set); MAV_FRAME_BODY_NED: velocity only,
rotated by the heading (any velocity bit set ignores all three); other frames are refused
("... coordinate frame N unsupported"); accelerations with FORCE_SET (512) are refused; yaw
(1024) and yaw rate (2048) likewise. A message with neither a position, a velocity nor an
acceleration is "SET_POSITION_TARGET_LOCAL_NED invalid". The emulator flies position (per axis)
with the velocity as feed-forward, or the velocity alone on an axis without a position;
accelerations count for validity (and as offboard proof of life) but are not flown, nor is the
yaw rate; a NaN yaw keeps the current heading.

Input hardening: a non-finite field that is used rejects the message; out-of-range values are
clamped (thrust to 0..1, rates to +-RATE_LIMIT, torques to -1..1) and reported as clamped; a
quaternion whose norm is not within 0.5..1.5 is rejected, otherwise normalised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vehicle_emulator.autopilots.demand import (
    ActuatorSetpoint,
    AttitudeSetpoint,
    OffboardSetpoint,
    PositionTarget,
    RatesSetpoint,
)
from vehicle_emulator.physics import frames

__all__ = [
    "Decoded",
    "PositionTargetFields",
    "from_actuator_control_target",
    "from_attitude_target",
    "from_position_target_local_ned",
]

RATE_LIMIT_RADPS = 10.0
IGNORE_ROLL_RATE = 1
IGNORE_PITCH_RATE = 2
IGNORE_YAW_RATE = 4
THRUST_BODY_SET = 32
IGNORE_THROTTLE = 64
IGNORE_ATTITUDE = 128
# POSITION_TARGET_TYPEMASK
POS_IGNORE_BITS = (1, 2, 4)
VEL_IGNORE_BITS = (8, 16, 32)
ACC_IGNORE_BITS = (64, 128, 256)
FORCE_SET = 512
YAW_IGNORE = 1024
YAW_RATE_IGNORE = 2048
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_LOCAL_OFFSET_NED = 7
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_OFFSET_NED = 9


@dataclass(frozen=True, slots=True)
class Decoded:
    """Outcome: a setpoint (or None), a rejection reason (or None), whether values were clamped."""

    setpoint: OffboardSetpoint | None
    rejected: str | None = None
    clamped: bool = False


def _clamp(x: float, lo: float, hi: float) -> tuple[float, bool]:
    y = min(max(x, lo), hi)
    return y, y != x


def _thrust(
    type_mask: int,
    thrust: float,
    thrust_body: Sequence[float] | None,
    attitude_branch: bool,
    previous_thrust: float | None,
) -> tuple[float | None, str | None, bool]:
    if type_mask & IGNORE_THROTTLE:
        if previous_thrust is None:
            return None, "throttle ignored and no previous thrust", False
        return previous_thrust, None, False
    if attitude_branch and type_mask & THRUST_BODY_SET and thrust_body is not None:
        value = -float(thrust_body[2])  # multicopter: collective = -thrust_body z (FRD)
    else:
        value = float(thrust)
    if not math.isfinite(value):
        return None, "thrust not finite", False
    t, c = _clamp(value, 0.0, 1.0)
    return t, None, c


def from_attitude_target(
    type_mask: int,
    q_wxyz: Sequence[float],
    body_rates_frd: Sequence[float],
    thrust: float,
    thrust_body: Sequence[float] | None = None,
    previous_thrust: float | None = None,
) -> Decoded:
    """SET_ATTITUDE_TARGET fields (NED/FRD) -> setpoint in ENU/FLU, per PX4's type_mask rules."""
    attitude_branch = not type_mask & IGNORE_ATTITUDE
    rates_branch = (
        not attitude_branch
        and not type_mask & IGNORE_ROLL_RATE
        and not type_mask & IGNORE_PITCH_RATE
    )
    if not attitude_branch and not rates_branch:
        return Decoded(None, "type_mask ignores attitude and roll/pitch rates")
    t, why, clamped = _thrust(type_mask, thrust, thrust_body, attitude_branch, previous_thrust)
    if t is None:
        return Decoded(None, why)
    yaw_ignored = bool(type_mask & IGNORE_YAW_RATE)
    if attitude_branch:
        q = np.asarray(q_wxyz, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)):
            return Decoded(None, "quaternion not finite")
        norm = float(np.linalg.norm(q))
        if not 0.5 <= norm <= 1.5:
            return Decoded(None, f"quaternion norm {norm:.3g} not ~1")
        clamped = clamped or abs(norm - 1.0) > 1e-3
        r_enu_flu = frames.rotation_enu_flu_from_ned_frd(frames.rotation_from_quaternion(q))
        yaw_ff = 0.0
        if not yaw_ignored:
            y = float(body_rates_frd[2])
            if not math.isfinite(y):
                return Decoded(None, "yaw rate not finite")
            y, c = _clamp(y, -RATE_LIMIT_RADPS, RATE_LIMIT_RADPS)
            clamped = clamped or c
            yaw_ff = -y  # FRD z (down) -> FLU z (up)
        return Decoded(AttitudeSetpoint(r_enu_flu, yaw_ff, t), None, clamped)
    # rates mode's hot path (one call per setpoint): written out, _clamp's rule per axis
    r0 = float(body_rates_frd[0])
    r1 = float(body_rates_frd[1])
    r2 = 0.0 if yaw_ignored else float(body_rates_frd[2])
    isfinite = math.isfinite
    if not (isfinite(r0) and isfinite(r1) and isfinite(r2)):
        return Decoded(None, "body rate not finite")
    lim = RATE_LIMIT_RADPS
    y0 = min(max(r0, -lim), lim)
    y1 = min(max(r1, -lim), lim)
    y2 = min(max(r2, -lim), lim)
    clamped = clamped or y0 != r0 or y1 != r1 or y2 != r2
    return Decoded(RatesSetpoint((y0, -y1, -y2), t), None, clamped)


def from_actuator_control_target(group: int, controls: Sequence[float]) -> Decoded:
    """SET_ACTUATOR_CONTROL_TARGET group 0: (roll, pitch, yaw) torque -1..1 FRD, thrust 0..1."""
    if group != 0:
        return Decoded(None, f"actuator group {group} not supported (only 0)")
    vals = [float(c) for c in controls[:4]]
    if len(vals) < 4 or not all(math.isfinite(x) for x in vals):
        return Decoded(None, "actuator control not finite")
    clamped = False
    tq = []
    for x in vals[:3]:
        y, c = _clamp(x, -1.0, 1.0)
        clamped = clamped or c
        tq.append(y)
    t, c = _clamp(vals[3], 0.0, 1.0)
    return Decoded(ActuatorSetpoint((tq[0], -tq[1], -tq[2]), t), None, clamped or c)


@dataclass(frozen=True, slots=True)
class PositionTargetFields:
    """SET_POSITION_TARGET_LOCAL_NED as sent (NED metres, m/s, m/s^2, rad), before any rule."""

    type_mask: int
    coordinate_frame: int
    position_ned_m: tuple[float, float, float]
    velocity_ned_mps: tuple[float, float, float]
    acceleration_ned_mps2: tuple[float, float, float]
    yaw_ned_rad: float
    yaw_rate_radps: float

    @classmethod
    def of(cls, m: Any) -> PositionTargetFields:
        """From a decoded SET_POSITION_TARGET_LOCAL_NED (the codec layer's message object)."""
        return cls(
            int(m.type_mask),
            int(m.coordinate_frame),
            (float(m.x), float(m.y), float(m.z)),
            (float(m.vx), float(m.vy), float(m.vz)),
            (float(m.afx), float(m.afy), float(m.afz)),
            float(m.yaw),
            float(m.yaw_rate),
        )


def _per_axis(values: Sequence[float], type_mask: int, bits: Sequence[int]) -> list[float]:
    """PX4: an ignored axis is NaN (not set)."""
    return [math.nan if type_mask & b else float(v) for v, b in zip(values, bits, strict=True)]


def from_position_target_local_ned(
    f: PositionTargetFields,
    origin_enu_m: tuple[float, float, float],
    position_enu_m: tuple[float, float, float],
    yaw_enu_rad: float,
) -> Decoded:
    """PX4's reading (module docstring) -> a PositionTarget in team ENU. ``origin_enu_m``: where
    the vehicle's local NED frame is zero; ``position_enu_m`` / ``yaw_enu_rad``: the vehicle now
    (kept on the axes the message leaves free and for a NaN yaw)."""
    mask = f.type_mask
    if f.coordinate_frame == MAV_FRAME_LOCAL_NED:
        pos = _per_axis(f.position_ned_m, mask, POS_IGNORE_BITS)
        vel = _per_axis(f.velocity_ned_mps, mask, VEL_IGNORE_BITS)
        acc = _per_axis(f.acceleration_ned_mps2, mask, ACC_IGNORE_BITS)
    elif f.coordinate_frame == MAV_FRAME_BODY_NED:
        pos = [math.nan] * 3
        heading_ned = frames.yaw_ned_from_yaw_enu(yaw_enu_rad)
        if any(mask & b for b in VEL_IGNORE_BITS):
            vel = [math.nan] * 3
        else:
            c, s = math.cos(heading_ned), math.sin(heading_ned)
            bx, by, bz = f.velocity_ned_mps
            vel = [c * bx - s * by, s * bx + c * by, bz]
        # PX4 rotates accelerations by the full attitude; they are not flown here
        acc = [math.nan] * 3 if any(mask & b for b in ACC_IGNORE_BITS) else [0.0, 0.0, 0.0]
    else:
        return Decoded(
            None, f"SET_POSITION_TARGET_LOCAL_NED coordinate frame {f.coordinate_frame} unsupported"
        )
    if any(math.isinf(x) for x in (*pos, *vel, *acc)):
        return Decoded(None, "position target not finite")
    has = [any(not math.isnan(x) for x in v) for v in (pos, vel, acc)]
    if has[2] and mask & FORCE_SET:
        return Decoded(None, "SET_POSITION_TARGET_LOCAL_NED force not supported")
    if not any(has):
        return Decoded(None, "SET_POSITION_TARGET_LOCAL_NED invalid")
    yaw_ned = math.nan if mask & YAW_IGNORE else f.yaw_ned_rad
    if math.isinf(yaw_ned):
        return Decoded(None, "position target yaw not finite")
    target = position_target_enu(pos, vel, origin_enu_m, position_enu_m, yaw_ned, yaw_enu_rad)
    return Decoded(target)


def position_target_enu(
    pos_ned: Sequence[float],
    vel_ned: Sequence[float],
    origin_enu_m: tuple[float, float, float],
    position_enu_m: tuple[float, float, float],
    yaw_ned_rad: float,
    yaw_enu_rad: float,
) -> PositionTarget:
    """Local-NED target with NaN for "not set" -> PositionTarget (team ENU): a set position
    axis is held (mask 1) with the velocity as feed-forward, an axis without one flies its
    velocity (0 if none); a NaN yaw keeps ``yaw_enu_rad``."""
    here_ned = frames.local_ned_from_enu(np.array(position_enu_m), origin_enu_m)
    p = [here_ned[k] if math.isnan(x) else x for k, x in enumerate(pos_ned)]
    target = frames.enu_from_local_ned(np.array(p), origin_enu_m)
    v_enu = frames.ned_to_enu(np.array([0.0 if math.isnan(x) else x for x in vel_ned]))
    m_ned = [0.0 if math.isnan(x) else 1.0 for x in pos_ned]
    yaw = yaw_enu_rad if math.isnan(yaw_ned_rad) else frames.yaw_enu_from_yaw_ned(yaw_ned_rad)
    return PositionTarget(
        (float(target[0]), float(target[1]), float(target[2])),
        (float(v_enu[0]), float(v_enu[1]), float(v_enu[2])),
        (m_ned[1], m_ned[0], m_ned[2]),  # NED axis order -> ENU
        yaw,
    )
