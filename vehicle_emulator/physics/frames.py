"""The emulator's only frame conversions: ENU/FLU (physics) <-> NED/FRD (MAVLink), quaternions.

Internal physics: world ENU (x east, y north, z up), body FLU (x forward, y left, z up).
MAVLink (PX4): world NED, body FRD, quaternion ``(w, x, y, z)`` of the rotation from NED to FRD,
i.e. the unit quaternion of ``R_ned_frd`` (columns: body FRD axes in NED coordinates), exactly as
PX4 fills ATTITUDE_QUATERNION, ODOMETRY and reads SET_ATTITUDE_TARGET.

    p_ned = P p_enu,   P = [[0,1,0],[1,0,0],[0,0,-1]]
    v_frd = F v_flu,   F = diag(1,-1,-1)
    R_ned_frd = P R_enu_flu F   (and back: R_enu_flu = P R_ned_frd F, both P, F involutions)

Every function is batched: vectors ``(n, 3)`` (or ``(3,)``), rotations ``(n, 3, 3)`` (or
``(3, 3)``), quaternions ``(n, 4)`` (or ``(4,)``). Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

P_ENU_NED: FloatArray = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
F_FLU_FRD: FloatArray = np.diag([1.0, -1.0, -1.0])

__all__ = [
    "F_FLU_FRD",
    "P_ENU_NED",
    "NedFrd",
    "Reported",
    "TelemetryNoise",
    "enu_from_local_ned",
    "enu_to_ned",
    "fleet_to_ned_frd",
    "local_ned_from_enu",
    "quat_from_matrix",
    "euler_ned_frd_from_rotation",
    "flu_to_frd",
    "frd_to_flu",
    "ned_to_enu",
    "quaternion_from_rotation",
    "rotation_enu_flu_from_ned_frd",
    "rotation_from_quaternion",
    "rotation_ned_frd_from_enu_flu",
    "yaw_ned_from_rotation_enu_flu",
    "rotation_enu_flu_from_yaw_ned",
    "yaw_enu_from_yaw_ned",
    "yaw_ned_from_yaw_enu",
]


def enu_to_ned(vector_enu: FloatArray) -> FloatArray:
    """World vector(s) ENU -> NED: swap x/y, negate z. Shape ``(..., 3)`` kept."""
    v = np.asarray(vector_enu, dtype=np.float64)
    return np.stack((v[..., 1], v[..., 0], -v[..., 2]), axis=-1)


ned_to_enu = enu_to_ned  # P is its own inverse


def enu_from_local_ned(
    position_ned_m: FloatArray, origin_enu_m: tuple[float, float, float]
) -> FloatArray:
    """A position in a vehicle's local NED frame (LOCAL_POSITION_NED, position targets) ->
    team ENU, given where that frame's zero is in the team frame
    (``VehicleSpec.local_origin_enu_m``)."""
    return ned_to_enu(position_ned_m) + np.asarray(origin_enu_m, dtype=np.float64)


def local_ned_from_enu(
    position_enu_m: FloatArray, origin_enu_m: tuple[float, float, float]
) -> FloatArray:
    """Team ENU position -> the vehicle's local NED frame (inverse of ``enu_from_local_ned``)."""
    return enu_to_ned(np.asarray(position_enu_m, dtype=np.float64) - np.asarray(origin_enu_m))


def yaw_enu_from_yaw_ned(yaw_ned_rad: float) -> float:
    """Heading NED (0 north, +east, MAVLink) -> ENU yaw (0 east, +north), wrapped to (-pi, pi]."""
    return math.remainder(0.5 * math.pi - yaw_ned_rad, 2.0 * math.pi)


yaw_ned_from_yaw_enu = yaw_enu_from_yaw_ned  # the map is its own inverse


def flu_to_frd(vector_flu: FloatArray) -> FloatArray:
    """Body vector(s) FLU -> FRD: negate y and z. Shape ``(..., 3)`` kept."""
    v = np.asarray(vector_flu, dtype=np.float64)
    return np.stack((v[..., 0], -v[..., 1], -v[..., 2]), axis=-1)


frd_to_flu = flu_to_frd  # F is its own inverse


def rotation_ned_frd_from_enu_flu(rotation_enu_flu: FloatArray) -> FloatArray:
    """``R_ned_frd = P R_enu_flu F`` for ``(..., 3, 3)`` body-to-world rotations."""
    r = np.asarray(rotation_enu_flu, dtype=np.float64)
    return P_ENU_NED @ r @ F_FLU_FRD


rotation_enu_flu_from_ned_frd = rotation_ned_frd_from_enu_flu  # same map both ways


def quaternion_from_rotation(rotation: FloatArray) -> FloatArray:
    """Unit quaternion(s) ``(w, x, y, z)`` with ``w >= 0`` of rotation matrices ``(..., 3, 3)``.

    Shepperd's method (branch on the largest diagonal term), vectorised.
    """
    r = np.asarray(rotation, dtype=np.float64)
    shape = r.shape[:-2]
    m = r.reshape(-1, 3, 3)
    q = np.empty((m.shape[0], 4))
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    cand = np.stack((trace, m00, m11, m22), axis=1)
    best = np.argmax(cand, axis=1)
    for k in range(4):
        sel = best == k
        if not np.any(sel):
            continue
        a = m[sel]
        if k == 0:
            s = 2.0 * np.sqrt(1.0 + trace[sel])
            q[sel] = np.stack(
                (
                    0.25 * s,
                    (a[:, 2, 1] - a[:, 1, 2]) / s,
                    (a[:, 0, 2] - a[:, 2, 0]) / s,
                    (a[:, 1, 0] - a[:, 0, 1]) / s,
                ),
                axis=1,
            )
        elif k == 1:
            s = 2.0 * np.sqrt(np.maximum(1.0 + a[:, 0, 0] - a[:, 1, 1] - a[:, 2, 2], 1e-300))
            q[sel] = np.stack(
                (
                    (a[:, 2, 1] - a[:, 1, 2]) / s,
                    0.25 * s,
                    (a[:, 0, 1] + a[:, 1, 0]) / s,
                    (a[:, 0, 2] + a[:, 2, 0]) / s,
                ),
                axis=1,
            )
        elif k == 2:
            s = 2.0 * np.sqrt(np.maximum(1.0 + a[:, 1, 1] - a[:, 0, 0] - a[:, 2, 2], 1e-300))
            q[sel] = np.stack(
                (
                    (a[:, 0, 2] - a[:, 2, 0]) / s,
                    (a[:, 0, 1] + a[:, 1, 0]) / s,
                    0.25 * s,
                    (a[:, 1, 2] + a[:, 2, 1]) / s,
                ),
                axis=1,
            )
        else:
            s = 2.0 * np.sqrt(np.maximum(1.0 + a[:, 2, 2] - a[:, 0, 0] - a[:, 1, 1], 1e-300))
            q[sel] = np.stack(
                (
                    (a[:, 1, 0] - a[:, 0, 1]) / s,
                    (a[:, 0, 2] + a[:, 2, 0]) / s,
                    (a[:, 1, 2] + a[:, 2, 1]) / s,
                    0.25 * s,
                ),
                axis=1,
            )
    q *= np.where(q[:, :1] < 0.0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(*shape, 4)


def rotation_from_quaternion(quaternion_wxyz: FloatArray) -> FloatArray:
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``(..., 4)`` (normalised first)."""
    q = np.asarray(quaternion_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def euler_ned_frd_from_rotation(rotation_ned_frd: FloatArray) -> FloatArray:
    """(roll, pitch, yaw) rad, ZYX Tait-Bryan of ``R_ned_frd`` as in MAVLink ATTITUDE."""
    r = np.asarray(rotation_ned_frd, dtype=np.float64)
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    pitch = np.arcsin(np.clip(-r[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    return np.stack((roll, pitch, yaw), axis=-1)


def yaw_ned_from_rotation_enu_flu(rotation_enu_flu: FloatArray) -> FloatArray:
    """Heading (NED yaw, rad, 0 = north, +east) of body-to-world ENU/FLU rotation(s)."""
    r = np.asarray(rotation_enu_flu, dtype=np.float64)
    # body x axis in ENU is column 0; NED yaw = atan2(east, north).
    return np.arctan2(r[..., 0, 0], r[..., 1, 0])


def rotation_enu_flu_from_yaw_ned(yaw_ned_rad: FloatArray | float) -> FloatArray:
    """Level attitude(s) ``R_enu_flu`` with the given NED heading(s)."""
    yaw = np.asarray(yaw_ned_rad, dtype=np.float64)
    enu_yaw = 0.5 * np.pi - yaw
    c, s = np.cos(enu_yaw), np.sin(enu_yaw)
    r = np.zeros(yaw.shape + (3, 3))
    r[..., 0, 0] = c
    r[..., 0, 1] = -s
    r[..., 1, 0] = s
    r[..., 1, 1] = c
    r[..., 2, 2] = 1.0
    return r


# --- numba versions for the hot paths (inner loops, telemetry) ---------------------------------


@njit(cache=True)
def quat_from_matrix(m: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a 3x3 rotation matrix (Shepperd), w >= 0."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr >= m[0, 0] and tr >= m[1, 1] and tr >= m[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + tr, 1e-300))
        w, x = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        y, z = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] >= m[1, 1] and m[0, 0] >= m[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 1e-300))
        w, x = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] >= m[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + m[1, 1] - m[0, 0] - m[2, 2], 1e-300))
        w, x = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 + m[2, 2] - m[0, 0] - m[1, 1], 1e-300))
        w, x = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        y, z = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return w, x, y, z


class Reported(NamedTuple):
    """What a vehicle's telemetry reports, per vehicle (ENU world, FLU body): attitude R_enu_flu,
    body rates, position, velocity, specific force (the truth, or the sensor model's)."""

    rot: FloatArray
    omega_radps: FloatArray
    pos_m: FloatArray
    vel_mps: FloatArray
    sf_mps2: FloatArray


class TelemetryNoise(NamedTuple):
    """White telemetry noise, one row per noisy vehicle: attitude (body rotation vector), body
    rates, position, velocity, specific force."""

    att_rad: FloatArray
    gyro_radps: FloatArray
    pos_m: FloatArray
    vel_mps: FloatArray
    acc_mps2: FloatArray


class NedFrd(NamedTuple):
    """The telemetry quantities in MAVLink's frames (NED world, FRD body) per vehicle:
    R_ned_frd, its quaternion (w, x, y, z) and Euler angles, body rates, position, velocity
    (world and body), specific force, the attitude and rate setpoints, heading."""

    r_ned: FloatArray
    q: FloatArray
    eul_rad: FloatArray
    w_frd_radps: FloatArray
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    vel_frd_mps: FloatArray
    acc_frd_mps2: FloatArray
    q_sp: FloatArray
    rate_sp_frd_radps: FloatArray
    yaw_ned_rad: FloatArray


@njit(cache=True)
def fleet_to_ned_frd(src, att_sp, rate_sp, rows, noisy, noise, out):
    """ENU/FLU fleet state ``src`` (`Reported`) and setpoints -> NED/FRD telemetry quantities
    ``out`` (`NedFrd`; see frames.py for the maps), for the vehicles ``rows`` (the others'
    outputs are left as they were); ``noisy`` (a subset of ``rows``) get the noise rows
    (`TelemetryNoise`) ``noise.*[k]`` for ``noisy[k]``. Each bundle may come as a plain tuple
    of its fields, as Telemetry passes them (numba types those faster)."""
    rot, omega, pos, vel, sf = src
    n_att, n_gyro, n_pos, n_vel, n_acc = noise
    r_ned, q, eul, w_frd, pos_ned, vel_ned, vel_frd, acc_frd, q_sp, rate_sp_frd, yaw_ned = out
    for i in rows:
        r = rot[i]
        # R_ned_frd = P R F: rows swapped (0<->1), row 2 negated; columns 1, 2 negated
        for c in range(3):
            s = 1.0 if c == 0 else -1.0
            r_ned[i, 0, c] = s * r[1, c]
            r_ned[i, 1, c] = s * r[0, c]
            r_ned[i, 2, c] = -s * r[2, c]
        w_frd[i, 0], w_frd[i, 1], w_frd[i, 2] = omega[i, 0], -omega[i, 1], -omega[i, 2]
        pos_ned[i, 0], pos_ned[i, 1], pos_ned[i, 2] = pos[i, 1], pos[i, 0], -pos[i, 2]
        vel_ned[i, 0], vel_ned[i, 1], vel_ned[i, 2] = vel[i, 1], vel[i, 0], -vel[i, 2]
        acc_frd[i, 0], acc_frd[i, 1], acc_frd[i, 2] = sf[i, 0], -sf[i, 1], -sf[i, 2]
        rate_sp_frd[i, 0] = rate_sp[i, 0]
        rate_sp_frd[i, 1] = -rate_sp[i, 1]
        rate_sp_frd[i, 2] = -rate_sp[i, 2]
        m = np.empty((3, 3))
        rs = att_sp[i]
        for c in range(3):
            s = 1.0 if c == 0 else -1.0
            m[0, c] = s * rs[1, c]
            m[1, c] = s * rs[0, c]
            m[2, c] = -s * rs[2, c]
        q_sp[i, 0], q_sp[i, 1], q_sp[i, 2], q_sp[i, 3] = quat_from_matrix(m)
    for k in range(noisy.shape[0]):
        i = noisy[k]
        # small rotation noise, applied in the body frame, then re-orthonormalised (Gram-Schmidt)
        dx, dy, dz = n_att[k, 0], n_att[k, 1], n_att[k, 2]
        a = r_ned[i].copy()
        for row in range(3):
            c0, c1, c2 = a[row, 0], a[row, 1], a[row, 2]
            r_ned[i, row, 0] = c0 + c1 * dz - c2 * dy
            r_ned[i, row, 1] = -c0 * dz + c1 + c2 * dx
            r_ned[i, row, 2] = c0 * dy - c1 * dx + c2
        x = r_ned[i, :, 0].copy()
        x /= math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
        y = r_ned[i, :, 1].copy()
        y -= (x[0] * y[0] + x[1] * y[1] + x[2] * y[2]) * x
        y /= math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2])
        z = np.cross(x, y)
        for row in range(3):
            r_ned[i, row, 0], r_ned[i, row, 1], r_ned[i, row, 2] = x[row], y[row], z[row]
        for j in range(3):
            w_frd[i, j] += n_gyro[k, j]
            pos_ned[i, j] += n_pos[k, j]
            vel_ned[i, j] += n_vel[k, j]
            acc_frd[i, j] += n_acc[k, j]
    for i in rows:
        a = r_ned[i]
        q[i, 0], q[i, 1], q[i, 2], q[i, 3] = quat_from_matrix(a)
        eul[i, 0] = math.atan2(a[2, 1], a[2, 2])
        eul[i, 1] = math.asin(min(max(-a[2, 0], -1.0), 1.0))
        eul[i, 2] = math.atan2(a[1, 0], a[0, 0])
        yaw_ned[i] = eul[i, 2]
        for j in range(3):  # body-frame velocity: R^T v
            vn = vel_ned[i]
            vel_frd[i, j] = a[0, j] * vn[0] + a[1, j] * vn[1] + a[2, j] * vn[2]
