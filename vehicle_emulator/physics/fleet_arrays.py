"""The fleet's per-vehicle arrays, grouped by what they are, as the compiled step takes them.

Each field is an array with one row per vehicle (the fleet's `Plant` owns them and updates them
in place); the compiled kernels (plant.py, onboard.py) unpack a group once per call. The
calibrated personalities' groups (`ImuModel` to `RateOutputs`, nested in `OnboardParams` and
`OnboardStates`) are `Onboard`'s arrays (onboard.py), bundled once; the kernels of sensors.py
and inner.py take them whole.
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


# --- the calibrated personalities' onboard model (onboard.py, sensors.py, inner.py) ------------


class ImuModel(NamedTuple):
    """The IMU model's parameters (personality.Sensors): EMU_NOISE, the white noise's 1 sigma
    per axis with the motors on and (gyro, accel) off, the gyro, D-term and accelerometer
    biquads (b0, b1, b2, a1, a2), and what HIGHRES_IMU reports (0 raw, 1 mean of two, 2
    filtered)."""

    noise_on: np.ndarray
    gyro_std_radps: np.ndarray
    accel_std_mps2: np.ndarray
    off_std: np.ndarray
    gyro_coef: np.ndarray
    dterm_coef: np.ndarray
    accel_coef: np.ndarray
    imu_mode: np.ndarray


class ImuState(NamedTuple):
    """The IMU model's state (FLU): filter states, the last raw samples, the filtered rate the
    rate loop flies on, its D-term derivative, and HIGHRES_IMU's gyro and accelerometer."""

    gyro_filter: np.ndarray
    dterm_filter: np.ndarray
    accel_filter: np.ndarray
    gyro_raw_radps: np.ndarray
    accel_raw_mps2: np.ndarray
    rate_meas_radps: np.ndarray
    dgyro_radps2: np.ndarray
    gyro_imu_radps: np.ndarray
    accel_imu_mps2: np.ndarray


class EstimateNoise(NamedTuple):
    """The estimate errors' sizes (stationary 1 sigma) and factors exp(-dt/tau) per control
    period: attitude (its second-order gain), velocity fast part and drift, and the position's
    decay and share of the velocity error (sensors.estimate_errors)."""

    attitude_std_rad: np.ndarray
    attitude_phi: np.ndarray
    attitude_smooth: np.ndarray
    velocity_std_mps: np.ndarray
    velocity_phi: np.ndarray
    drift_std_mps: np.ndarray
    drift_phi: np.ndarray
    position_phi: np.ndarray
    position_share: np.ndarray


class EstimateErrors(NamedTuple):
    """The estimate errors now: attitude (body axes; its first stage), velocity (its fast and
    drift parts; ENU) and position (ENU)."""

    attitude_stage: np.ndarray
    attitude_rad: np.ndarray
    velocity_parts_mps: np.ndarray
    velocity_mps: np.ndarray
    position_m: np.ndarray


class Px4RateGains(NamedTuple):
    """PX4's rate loop (inner.px4_rate_control): PID gains, integrator limit, the yaw torque
    low pass's factor and the torque authority [rad/s^2 per normalised unit]."""

    gain_p: np.ndarray
    gain_i: np.ndarray
    gain_d: np.ndarray
    int_limit: np.ndarray
    yaw_alpha: np.ndarray
    accel_per_unit_radps2: np.ndarray


class ReferenceGains(NamedTuple):
    """The fitted reference model of a rate response (inner.reference_rate_control): slew
    limit, input gains, the exact 2nd-order step (Phi row-major, Gamma), the tracking loop's
    (kp, ki) and the dead time in control periods."""

    accel_max_radps2: np.ndarray
    ref_gain: np.ndarray
    ref_phi: np.ndarray
    ref_gamma: np.ndarray
    angle_p: np.ndarray
    track: np.ndarray
    delay_periods: np.ndarray


class ReferenceState(NamedTuple):
    """The reference model's state: shaped command, (rate, rate') reference, angle error,
    tracking integral, the dead time's ring buffer and its write position."""

    shaped_radps: np.ndarray
    ref: np.ndarray
    angle_err_rad: np.ndarray
    track_int: np.ndarray
    delay_buf: np.ndarray
    delay_idx: np.ndarray


class RateOutputs(NamedTuple):
    """What a calibrated rate loop writes and reads back: this period's torque [N m], PX4's
    yaw torque low pass, the mixer's saturation flags (+1 short, -1 beyond), and the output
    delay line (next period's torque and normalised thrust)."""

    torque_nm: np.ndarray
    yaw_torque_lpf: np.ndarray
    limited: np.ndarray
    torque_next_nm: np.ndarray
    thrust_next_norm: np.ndarray


class OnboardParams(NamedTuple):
    """The calibrated personalities' parameters (Onboard.params(), built once)."""

    rate_loop: np.ndarray
    angular_damping_per_s: np.ndarray
    drag_decay: np.ndarray
    linear_drag_per_s: np.ndarray
    thrust_scale: np.ndarray
    control_div: np.ndarray
    imu: ImuModel
    position_delay: np.ndarray
    output_delay: np.ndarray
    px4: Px4RateGains
    reference: ReferenceGains
    estimate: EstimateNoise
    disturbance_std: np.ndarray
    gyro_integration_phi: np.ndarray
    gyro_bias_std: np.ndarray
    gyro_bias_phi: np.ndarray
    disturbance_ar: np.ndarray
    hold_wander_std: np.ndarray
    hold_wander_ar: np.ndarray


class OnboardStates(NamedTuple):
    """The calibrated personalities' states (Onboard.states(), built once): the noise
    generators, the IMU model, the rate loops, the latched estimates and their sample steps,
    the estimate errors, gyro bias, process noise and hold wander."""

    rng: np.ndarray
    imu: ImuState
    rate_out: RateOutputs
    reference: ReferenceState
    rotation_est: np.ndarray
    position_est_m: np.ndarray
    velocity_est_mps: np.ndarray
    position_prev_m: np.ndarray
    velocity_prev_mps: np.ndarray
    attitude_step: np.ndarray
    position_step: np.ndarray
    position_prev_step: np.ndarray
    errors: EstimateErrors
    integration_error: np.ndarray
    gyro_bias: np.ndarray
    disturbance_state: np.ndarray
    wander_state: np.ndarray
    wander_m: np.ndarray
    wandered_sp_m: np.ndarray
