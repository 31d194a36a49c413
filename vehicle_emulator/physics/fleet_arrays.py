"""The fleet's per-vehicle arrays, grouped by what they are, as the compiled step takes them.

Each field is an array with one row per vehicle (the fleet's `Plant` owns them and updates them
in place); the compiled kernels (plant.py, onboard.py) unpack a group once per call.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Commands(NamedTuple):
    """What the autopilot asks of the inner loops (world ENU, body FLU, normalised thrust)."""

    mode: np.ndarray  # ControlMode per vehicle
    thrust_cmd: np.ndarray
    rate_cmd: np.ndarray
    att_cmd: np.ndarray
    yaw_rate_ff: np.ndarray
    torque_cmd: np.ndarray
    pos_sp: np.ndarray
    vel_ff: np.ndarray
    pos_mask: np.ndarray
    yaw_sp: np.ndarray
    hover: np.ndarray


class LoopState(NamedTuple):
    """The inner loops' setpoints and integrators, held between control periods."""

    att_sp: np.ndarray
    rate_sp: np.ndarray
    thrust_sp: np.ndarray
    torque_sp: np.ndarray
    rate_int: np.ndarray
    omega_prev: np.ndarray
    vel_int: np.ndarray


class Body(NamedTuple):
    """The rigid body's true state: position, velocity (ENU), attitude, body rates (FLU)."""

    pos: np.ndarray
    vel: np.ndarray
    rot: np.ndarray
    omega: np.ndarray


class Airframe(NamedTuple):
    """Mass, inertia, geometry and the rotors' limits and lags."""

    mass: np.ndarray
    inertia: np.ndarray
    arm: np.ndarray
    anti: np.ndarray
    fmax: np.ndarray
    tmax: np.ndarray
    motor_tau: np.ndarray
    airmode: np.ndarray
    eff: np.ndarray


class Outputs(NamedTuple):
    """What a step leaves for telemetry and the autopilots: rotor commands and thrusts, the
    body wrench, ground contact, the accelerometer's specific force, charge used."""

    rotor_cmd: np.ndarray
    rotor_f: np.ndarray
    thrust_n: np.ndarray
    torque_n: np.ndarray
    on_ground: np.ndarray
    impact_speed: np.ndarray
    touchdowns: np.ndarray
    sf_body: np.ndarray
    charge_c: np.ndarray
    t_sp_n: np.ndarray
