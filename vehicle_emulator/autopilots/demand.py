"""What an autopilot knows of its vehicle and asks its inner loops to fly; MAVLink's result
and severity codes. Shared by the PX4 and ArduPilot state machines. Pure.

A demand is one of: rotors stopped (`MotorsOff`), idle on the ground (`Idle`), a position
target (`PositionTarget`, also the takeoff climb and the landing descent) or an offboard
setpoint (rates, attitude or actuators) held until the next.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

__all__ = [
    "ActuatorSetpoint", "AttitudeSetpoint", "Demand", "Idle", "MavResult", "MotorsOff",
    "Observation", "OffboardSetpoint", "PositionTarget", "RatesSetpoint", "Severity", "capture",
    "climb", "descent", "hold",
]


class MavResult(IntEnum):
    """MAV_RESULT."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class Severity(IntEnum):
    """MAV_SEVERITY."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


@dataclass(frozen=True, slots=True)
class Observation:
    """What the autopilot knows of its vehicle (ENU world, metres, radians)."""

    position_enu_m: tuple[float, float, float]
    velocity_enu_mps: tuple[float, float, float]
    yaw_enu_rad: float
    on_ground: bool
    battery_remaining: float = 1.0


@dataclass(frozen=True, slots=True)
class RatesSetpoint:
    """Body rates (FLU, rad/s) and collective thrust normalised 0..1 (of 4 f_max)."""

    rate_flu_radps: tuple[float, float, float]
    thrust_norm: float


@dataclass(frozen=True, slots=True)
class AttitudeSetpoint:
    """Attitude R_enu_flu (3x3), yaw-rate feed-forward (FLU z, rad/s), normalised thrust."""

    rotation_enu_flu: np.ndarray
    yaw_rate_ff_flu_radps: float
    thrust_norm: float


@dataclass(frozen=True, slots=True)
class ActuatorSetpoint:
    """Normalised torques (FLU, -1..1, see plant.torque_max_nm) and normalised thrust 0..1."""

    torque_norm_flu: tuple[float, float, float]
    thrust_norm: float


@dataclass(frozen=True, slots=True)
class PositionTarget:
    """Onboard position controller target: ENU position, velocity feed-forward, per-axis mask
    (1: hold the position on that axis, 0: fly the feed-forward velocity only), ENU heading."""

    position_enu_m: tuple[float, float, float]
    velocity_ff_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mask: tuple[float, float, float] = (1.0, 1.0, 1.0)
    yaw_enu_rad: float = 0.0


@dataclass(frozen=True, slots=True)
class MotorsOff:
    """Disarmed: rotors stopped."""


@dataclass(frozen=True, slots=True)
class Idle:
    """Armed on the ground: idle thrust, no torque."""


Demand = MotorsOff | Idle | PositionTarget | RatesSetpoint | AttitudeSetpoint | ActuatorSetpoint
OffboardSetpoint = RatesSetpoint | AttitudeSetpoint | ActuatorSetpoint | PositionTarget


def hold(armed: bool, obs: Observation) -> Demand:
    """Hold where the vehicle is: rotors off disarmed, idle on the ground, else a position
    target here at the present heading."""
    if not armed:
        return MotorsOff()
    if obs.on_ground:
        return Idle()
    return PositionTarget(obs.position_enu_m, yaw_enu_rad=obs.yaw_enu_rad)


def descent(obs: Observation, speed_mps: float) -> Demand:
    """Descend at ``speed_mps`` holding x and y (idle once on the ground)."""
    if obs.on_ground:
        return Idle()
    return PositionTarget(
        obs.position_enu_m, (0.0, 0.0, -speed_mps), (1.0, 1.0, 0.0), obs.yaw_enu_rad
    )


def climb(obs: Observation, alt_m: float, speed_mps: float) -> PositionTarget:
    """Climb at ``speed_mps`` to ``alt_m`` above x, y here (z on velocity alone)."""
    return PositionTarget((obs.position_enu_m[0], obs.position_enu_m[1], alt_m),
                          (0.0, 0.0, speed_mps), (1.0, 1.0, 0.0), obs.yaw_enu_rad)


def capture(climbing: PositionTarget, alt_m: float) -> PositionTarget:
    """The climb's end: hold ``alt_m`` on position over the climb's x, y and heading."""
    return PositionTarget((climbing.position_enu_m[0], climbing.position_enu_m[1], alt_m),
                          yaw_enu_rad=climbing.yaw_enu_rad)
