"""SET_ATTITUDE_TARGET / SET_ACTUATOR_CONTROL_TARGET fields -> checked offboard setpoints. Pure.

PX4's type_mask rules (spec/mavlink.md): bits set = ignore (1 roll rate, 2 pitch rate, 4 yaw rate,
64 throttle, 128 attitude; 32 = use thrust_body). If bit 128 is clear the quaternion is the
setpoint (attitude wins) and a non-ignored yaw rate is a feed-forward; else body rates are used
only if roll AND pitch rates are both not ignored (an ignored yaw rate then means 0). Otherwise
the message carries no setpoint and is ignored (it does not feed the offboard stream).

Input hardening: a non-finite field that is used rejects the message; out-of-range values are
clamped (thrust to 0..1, rates to +-RATE_LIMIT, torques to -1..1) and reported as clamped; a
quaternion whose norm is not within 0.5..1.5 is rejected, otherwise normalised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vehicle_emulator import frames
from vehicle_emulator.autopilot import (
    ActuatorSetpoint,
    AttitudeSetpoint,
    OffboardSetpoint,
    RatesSetpoint,
)

__all__ = ["Decoded", "from_actuator_control_target", "from_attitude_target"]

RATE_LIMIT_RADPS = 10.0
IGNORE_ROLL_RATE = 1
IGNORE_PITCH_RATE = 2
IGNORE_YAW_RATE = 4
THRUST_BODY_SET = 32
IGNORE_THROTTLE = 64
IGNORE_ATTITUDE = 128


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
    rates = [
        float(body_rates_frd[0]),
        float(body_rates_frd[1]),
        0.0 if yaw_ignored else float(body_rates_frd[2]),
    ]
    if not all(math.isfinite(x) for x in rates):
        return Decoded(None, "body rate not finite")
    out = []
    for x in rates:
        y, c = _clamp(x, -RATE_LIMIT_RADPS, RATE_LIMIT_RADPS)
        clamped = clamped or c
        out.append(y)
    flu = (out[0], -out[1], -out[2])
    return Decoded(RatesSetpoint(flu, t), None, clamped)


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
