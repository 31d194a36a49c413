"""Onboard inner-loop controllers (PX4-like cascade), per vehicle, numba njit, pure.

All vectors ENU world / FLU body. Each function works on vehicle ``i`` of batched arrays and is
called from the fleet kernel in plant.py at the physics rate (1 kHz by default).

* ``rate_control``: body-rate PID + feed-forward (PX4 ``RateControl``), written in angular
  acceleration units and scaled by the true inertia: ``tau = J (Kp e + I - Kd dw/dt + Kff w_sp)
  + w x J w``; integrator clamped and held while landed.
* ``attitude_control``: PX4's quaternion P law ``w_sp = K 2 sign(qe_w) qe_xyz`` with
  ``qe = q^-1 q_sp`` (body frame) plus a yaw-rate feed-forward, clipped to the max rates.
* ``position_control``: position P -> velocity PI -> thrust vector (hover thrust scaled, PX4
  ``MPC_THR_HOVER`` style, tilt limited) -> attitude setpoint with a heading.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from flightkit.physics import GRAVITY_MPS2
from vehicle_emulator.physics.fleet_arrays import (
    Body,
    Commands,
    ImuState,
    LoopState,
    Px4RateGains,
    RateOutputs,
    ReferenceGains,
    ReferenceState,
)
from vehicle_emulator.physics.frames import quat_from_matrix

# Gains (rad/s^2 per rad/s for rates; 1/s for attitude and position; 1/s^2 for velocity I).
RATE_P = np.array([40.0, 40.0, 20.0])
RATE_I = np.array([30.0, 30.0, 10.0])
RATE_D = np.array([0.0, 0.0, 0.0])
RATE_FF = np.array([0.0, 0.0, 0.0])
RATE_I_LIMIT = np.array([10.0, 10.0, 5.0])  # rad/s^2
RATE_MAX = np.array([3.84, 3.84, 3.49])  # PX4 MC_*RATE_MAX defaults: 220, 220, 200 deg/s
ATT_P = np.array([6.5, 6.5, 2.8])  # PX4 MC_ROLL_P, MC_PITCH_P, MC_YAW_P
POS_P = np.array([0.95, 0.95, 1.0])  # PX4 MPC_XY_P, MPC_Z_P
VEL_P = np.array([1.8, 1.8, 4.0])  # PX4 MPC_XY_VEL_P_ACC, MPC_Z_VEL_P_ACC
VEL_I = np.array([0.4, 0.4, 2.0])  # PX4 MPC_XY_VEL_I_ACC, MPC_Z_VEL_I_ACC
VEL_I_LIMIT = np.array([3.0, 3.0, 6.0])  # m/s^2
VEL_XY_MAX = 5.0
VEL_UP_MAX = 3.0
VEL_DOWN_MAX = 1.5
TILT_MAX_RAD = math.radians(45.0)
THRUST_MIN_NORM = 0.05


@njit(cache=True)
def rate_control(
    i: int,
    rate_sp: np.ndarray,
    omega: np.ndarray,
    omega_prev: np.ndarray,
    rate_int: np.ndarray,
    inertia: np.ndarray,
    landed: bool,
    dt: float,
    torque_out: np.ndarray,
) -> None:
    """Body torque [N m, FLU] into ``torque_out[i]`` for rate setpoint ``rate_sp[i]`` (rad/s)."""
    w0, w1, w2 = omega[i, 0], omega[i, 1], omega[i, 2]
    alpha = np.empty(3)
    for k in range(3):
        e = rate_sp[i, k] - omega[i, k]
        d = (omega[i, k] - omega_prev[i, k]) / dt
        if not landed:
            v = rate_int[i, k] + RATE_I[k] * e * dt
            rate_int[i, k] = min(max(v, -RATE_I_LIMIT[k]), RATE_I_LIMIT[k])
        else:
            rate_int[i, k] = 0.0
        alpha[k] = RATE_P[k] * e + rate_int[i, k] - RATE_D[k] * d + RATE_FF[k] * rate_sp[i, k]
        omega_prev[i, k] = omega[i, k]
    jx, jy, jz = inertia[i, 0], inertia[i, 1], inertia[i, 2]
    # + w x (J w): cancels the gyroscopic term of eq. (9)
    torque_out[i, 0] = jx * alpha[0] + (w1 * jz * w2 - w2 * jy * w1)
    torque_out[i, 1] = jy * alpha[1] + (w2 * jx * w0 - w0 * jz * w2)
    torque_out[i, 2] = jz * alpha[2] + (w0 * jy * w1 - w1 * jx * w0)


@njit(cache=True)
def attitude_control(
    i: int,
    rotation: np.ndarray,
    rotation_sp: np.ndarray,
    yaw_rate_ff: np.ndarray,
    rate_sp_out: np.ndarray,
) -> None:
    """Rate setpoint (FLU, rad/s) into ``rate_sp_out[i]`` for attitude ``rotation_sp[i]``."""
    r = rotation[i]
    rs = rotation_sp[i]
    err = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            err[a, b] = r[0, a] * rs[0, b] + r[1, a] * rs[1, b] + r[2, a] * rs[2, b]
    w, x, y, z = quat_from_matrix(err)  # w >= 0: shortest way
    e = (2.0 * x, 2.0 * y, 2.0 * z)
    for k in range(3):
        v = ATT_P[k] * e[k]
        if k == 2:
            v += yaw_rate_ff[i]
        rate_sp_out[i, k] = min(max(v, -RATE_MAX[k]), RATE_MAX[k])


@njit(cache=True)
def attitude_from_thrust_vector(
    i: int, tx: float, ty: float, tz: float, yaw_enu: float, rotation_sp_out: np.ndarray
) -> None:
    """R_sp with body z along (tx, ty, tz) and the body x axis heading ``yaw_enu`` (ENU, rad)."""
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n < 1e-9:
        tx, ty, tz, n = 0.0, 0.0, 1.0, 1.0
    zx, zy, zz = tx / n, ty / n, tz / n
    cx, cy = math.cos(yaw_enu), math.sin(yaw_enu)
    # y_b = z_b x x_c, with x_c = (cx, cy, 0)
    yx, yy, yz = -zz * cy, zz * cx, zx * cy - zy * cx
    ny = math.sqrt(yx * yx + yy * yy + yz * yz)
    if ny < 1e-9:  # z_b horizontal along the heading: pick any orthogonal y
        yx, yy, yz, ny = -cy, cx, 0.0, 1.0
    yx, yy, yz = yx / ny, yy / ny, yz / ny
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    m = rotation_sp_out[i]
    m[0, 0], m[1, 0], m[2, 0] = xx, xy, xz
    m[0, 1], m[1, 1], m[2, 1] = yx, yy, yz
    m[0, 2], m[1, 2], m[2, 2] = zx, zy, zz


@njit(cache=True, inline="always")
def position_control(i: int, body: Body, cmd: Commands, loops: LoopState, landed: bool,
                     dt: float) -> float:
    """Attitude setpoint into ``loops.att_sp[i]``; returns normalised collective thrust.

    ``body`` (`Body`): the position, velocity and attitude the loop flies on; ``cmd``
    (`Commands`): position setpoint, velocity feed-forward, mask, yaw setpoint and hover
    thrust; ``loops`` (`LoopState`): the velocity integrator and the attitude setpoint.
    ``pos_mask[i, k]`` 1 uses the position error on axis k, 0 flies the velocity ``vel_ff`` only
    (landing: z masked with a downward velocity).
    """
    position, velocity, rotation = body.pos, body.vel, body.rot
    pos_sp, vel_ff, pos_mask = cmd.pos_sp, cmd.vel_ff, cmd.pos_mask
    yaw_sp_enu, hover_thrust_norm = cmd.yaw_sp, cmd.hover
    vel_int, rotation_sp_out = loops.vel_int, loops.att_sp
    vs = np.empty(3)
    for k in range(3):
        vs[k] = POS_P[k] * (pos_sp[i, k] - position[i, k]) * pos_mask[i, k] + vel_ff[i, k]
    hxy = math.sqrt(vs[0] * vs[0] + vs[1] * vs[1])
    if hxy > VEL_XY_MAX:
        vs[0] *= VEL_XY_MAX / hxy
        vs[1] *= VEL_XY_MAX / hxy
    vs[2] = min(max(vs[2], -VEL_DOWN_MAX - max(0.0, -vel_ff[i, 2])), VEL_UP_MAX)
    acc = np.empty(3)
    for k in range(3):
        e = vs[k] - velocity[i, k]
        if not landed:
            v = vel_int[i, k] + VEL_I[k] * e * dt
            vel_int[i, k] = min(max(v, -VEL_I_LIMIT[k]), VEL_I_LIMIT[k])
        acc[k] = VEL_P[k] * e + vel_int[i, k]
    hover = hover_thrust_norm[i]
    tx = acc[0] / GRAVITY_MPS2 * hover
    ty = acc[1] / GRAVITY_MPS2 * hover
    tz = (acc[2] / GRAVITY_MPS2 + 1.0) * hover
    tz = max(tz, THRUST_MIN_NORM)
    # tilt limit: horizontal part at most tan(tilt_max) * vertical part
    h = math.sqrt(tx * tx + ty * ty)
    h_max = tz * math.tan(TILT_MAX_RAD)
    if h > h_max:
        tx *= h_max / h
        ty *= h_max / h
    mag = math.sqrt(tx * tx + ty * ty + tz * tz)
    if mag > 1.0:
        tx, ty, tz, mag = tx / mag, ty / mag, tz / mag, 1.0
    attitude_from_thrust_vector(i, tx, ty, tz, yaw_sp_enu[i], rotation_sp_out)
    # PX4 projects the thrust vector on the current body z axis
    r = rotation[i]
    proj = tx * r[0, 2] + ty * r[1, 2] + tz * r[2, 2]
    return min(max(proj, 0.0), 1.0)


# --- calibrated personalities (personality.Dynamics; docs/emulator.md "Calibration") -----------

PX4_I_FACTOR_RADPS = math.radians(400.0)  # RateControl: I gain fades with the rate error


@njit(cache=True, inline="always")
def px4_rate_control(i: int, loops: LoopState, imu: ImuState, gains: Px4RateGains,
                     inertia: np.ndarray, out: RateOutputs, landed: bool, dt: float) -> None:
    """PX4's RateControl::update on the filtered gyro ``rate_meas[i]`` (FLU; PX4 runs it in FRD,
    which flips the signs of both sides alike): normalised torque ``P e + I - D dgyro``, the I term
    fading with |e| (i_factor) and clamped, frozen while landed and, on an axis the mixer
    saturated (``limited[i]``: +1 short of the demand, -1 beyond it), never integrating further
    into that saturation (PX4's control-allocator saturation flags); yaw through the
    MC_YAW_TQ_CUTOFF first-order low pass; each axis clipped to +-1, then scaled to N m by
    ``accel_per_unit`` times the vehicle's inertia into ``torque_out[i]``. ``loops``
    (`LoopState`): rate_sp, rate_int; ``imu`` (`ImuState`): rate_meas, dgyro; ``gains``
    (`Px4RateGains`); ``out`` (`RateOutputs`): torque_out, yaw_lpf, limited."""
    rate_sp, rate_int = loops.rate_sp, loops.rate_int
    rate_meas, dgyro = imu.rate_meas_radps, imu.dgyro_radps2
    gain_p, gain_i, gain_d, int_limit, yaw_alpha, accel_per_unit = gains
    torque_out, yaw_lpf, limited = out.torque_nm, out.yaw_torque_lpf, out.limited
    for k in range(3):
        e = rate_sp[i, k] - rate_meas[i, k]
        u = gain_p[i, k] * e + rate_int[i, k] - gain_d[i, k] * dgyro[i, k]
        if not landed:
            if limited[i, k] > 0.0:
                e = min(e, 0.0)
            elif limited[i, k] < 0.0:
                e = max(e, 0.0)
            f = e / PX4_I_FACTOR_RADPS
            f = max(0.0, 1.0 - f * f)
            v = rate_int[i, k] + f * gain_i[i, k] * e * dt
            rate_int[i, k] = min(max(v, -int_limit[i, k]), int_limit[i, k])
        if k == 2:
            yaw_lpf[i] += yaw_alpha[i] * (u - yaw_lpf[i])
            u = yaw_lpf[i]
        u = min(max(u, -1.0), 1.0)
        torque_out[i, k] = inertia[i, k] * accel_per_unit[i, k] * u


@njit(cache=True, inline="always")
def reference_rate_control(i: int, loops: LoopState, imu: ImuState, body: Body,
                           gains: ReferenceGains, st: ReferenceState, inertia: np.ndarray,
                           out: RateOutputs, landed: bool, dt: float) -> None:
    """A fitted closed-loop model of an autopilot's rate response, per body axis (FLU), from
    ``loops.rate_sp``, the raw gyro ``imu.gyro_raw`` and the true ``body.omega``, with the
    model ``gains`` (`ReferenceGains`) and its state ``st`` (`ReferenceState`): the
    command slews at most ``accel_max`` (ArduPilot's ATC_ACCEL_*_MAX input shaping) to
    ``shaped``; the angle error ``angle_err`` integrates shaped minus raw gyro rate (an attitude
    estimate's error, not the filtered rate's); the reference
    ``ref[i, k] = (rate, rate')`` is a 2nd-order system driven by ``ref_gain * shaped + angle_p *
    angle_err`` delayed by ``delay_n[i, k]`` periods (ring ``delay_buf[i, k]``, write position
    ``delay_idx[i]``), stepped exactly (``ref_phi`` (2x2 row-major), ``ref_gamma``); the body
    follows it
    through a stiff loop on the raw gyro with the reference acceleration fed forward, plus the
    gyroscopic term: torque = J (rate' + kp e + ki int e) + w x J w into ``out.torque[i]``. On
    an axis the mixer saturated (``out.limited[i, k]`` nonzero) the integral may only shrink
    (ArduPilot's AC_PID with the motors' limit flags)."""
    rate_sp, gyro_raw, omega = loops.rate_sp, imu.gyro_raw_radps, body.omega
    accel_max, ref_gain, ref_phi, ref_gamma, angle_p, track, delay_n = gains
    shaped, ref, angle_err, track_int, delay_buf, delay_idx = st
    torque_out, limited = out.torque_nm, out.limited
    kp, ki = track[i, 0], track[i, 1]
    for k in range(3):
        step = accel_max[i, k] * dt
        s = shaped[i, k]
        s += min(max(rate_sp[i, k] - s, -step), step)
        shaped[i, k] = s
        if landed:
            angle_err[i, k] = 0.0
            track_int[i, k] = 0.0
        else:
            a = angle_err[i, k] + (s - gyro_raw[i, k]) * dt
            angle_err[i, k] = min(max(a, -0.5), 0.5)
        u = ref_gain[i, k] * s + angle_p[i, k] * angle_err[i, k]
        size = delay_buf.shape[2]
        j = delay_idx[i]
        delay_buf[i, k, j] = u
        u = delay_buf[i, k, (j - delay_n[i, k]) % size]
        x1, x2 = ref[i, k, 0], ref[i, k, 1]
        p = ref_phi[i, k]
        ref[i, k, 0] = p[0] * x1 + p[1] * x2 + ref_gamma[i, k, 0] * u
        ref[i, k, 1] = p[2] * x1 + p[3] * x2 + ref_gamma[i, k, 1] * u
        e = ref[i, k, 0] - gyro_raw[i, k]
        if not landed and (limited[i, k] == 0.0 or track_int[i, k] * e < 0.0):
            track_int[i, k] = min(max(track_int[i, k] + ki * e * dt, -20.0), 20.0)
        torque_out[i, k] = inertia[i, k] * (ref[i, k, 1] + kp * e + track_int[i, k])
    delay_idx[i] = (delay_idx[i] + 1) % delay_buf.shape[2]
    w0, w1, w2 = omega[i, 0], omega[i, 1], omega[i, 2]
    jx, jy, jz = inertia[i, 0], inertia[i, 1], inertia[i, 2]
    torque_out[i, 0] += w1 * jz * w2 - w2 * jy * w1
    torque_out[i, 1] += w2 * jx * w0 - w0 * jz * w2
    torque_out[i, 2] += w0 * jy * w1 - w1 * jx * w0


def second_order_step(wn_radps: float, zeta: float, dt_s: float) -> tuple[tuple, tuple]:
    """Exact zero-order-hold step of x'' = wn^2 (u - x) - 2 zeta wn x' over dt_s:
    ((phi00, phi01, phi10, phi11), (gamma0, gamma1)) with (x, x')_next = Phi (x, x') + Gamma u.
    Closed form of expm for the companion matrix (any zeta > 0)."""
    if not (wn_radps > 0.0 and zeta > 0.0 and dt_s > 0.0):
        raise ValueError(f"second-order reference needs wn, zeta, dt > 0, got {wn_radps}, "
                         f"{zeta}, {dt_s}")
    s = -zeta * wn_radps  # e^{A t} = e^{s t} (c(t) I + g(t) (A - s I)), q^2 = s^2 - wn^2
    q2 = s * s - wn_radps * wn_radps
    t = dt_s
    if abs(q2) < 1e-12:
        c, g = 1.0, t
    elif q2 > 0.0:
        q = math.sqrt(q2)
        c, g = math.cosh(q * t), math.sinh(q * t) / q
    else:
        q = math.sqrt(-q2)
        c, g = math.cos(q * t), math.sin(q * t) / q
    e = math.exp(s * t)
    # A - s I = [[-s, 1], [-wn^2, -2 zeta wn - s]]
    phi = (e * (c - g * s), e * g, -e * g * wn_radps**2, e * (c + g * (-2.0 * zeta * wn_radps - s)))
    # Gamma = A^-1 (Phi - I) B with B = (0, wn^2): A^-1 = [[-2 zeta / wn, -1 / wn^2], [1, 0]]
    d0, d1 = phi[1] * wn_radps**2, (phi[3] - 1.0) * wn_radps**2
    gamma = (-2.0 * zeta / wn_radps * d0 - d1 / wn_radps**2, d0)
    return phi, gamma
