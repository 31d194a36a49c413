"""The only place in gcs converting between MAVLink NED/FRD and the app's ENU/FLU frames.

Conventions
-----------
- World: the app uses ENU (x east, y north, z up; the paper's z-up frame); MAVLink uses local NED.
  ``p_ned = P @ p_enu`` with ``P = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]``; ``P`` is its own inverse.
- Body: the app uses FLU (x forward, y left, z up); MAVLink uses FRD.
  ``v_frd = F @ v_flu`` with ``F = diag(1, -1, -1)``; ``F`` is its own inverse.
- Attitude: a rotation matrix maps body coordinates to world coordinates, so
  ``R_ned_frd = P @ R_enu_flu @ F`` (and the same expression maps back).
- Quaternions: MAVLink sends Hamilton quaternions ordered (w, x, y, z) of ``R_ned_frd`` (body FRD
  -> NED); scipy orders them (x, y, z, w). Quaternions returned here have w >= 0.
- Euler angles (MAVLink ATTITUDE): roll, pitch, yaw about FRD, ZYX order:
  ``R_ned_frd = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.

Every function accepts a single item (shape (3,), (3, 3), (4,)) or a batch with any leading shape
((n, 3), (n, 3, 3), (n, 4)) and returns float64 arrays of the matching shape. Pure numpy, no I/O.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: World-frame swap: p_ned = P_NED_ENU @ p_enu, and p_enu = P_NED_ENU @ p_ned.
P_NED_ENU: FloatArray = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: Body-frame flip: v_frd = F_FRD_FLU @ v_flu, and v_flu = F_FRD_FLU @ v_frd.
F_FRD_FLU: FloatArray = np.diag([1.0, -1.0, -1.0])
P_NED_ENU.setflags(write=False)
F_FRD_FLU.setflags(write=False)


def _vectors(v: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), got {arr.shape}")
    return arr


def _matrices(m: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(m, dtype=np.float64)
    if arr.ndim < 2 or arr.shape[-2:] != (3, 3):
        raise ValueError(f"{name}: expected shape (..., 3, 3), got {arr.shape}")
    return arr


def _quaternions(q: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(q, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 4:
        raise ValueError(f"{name}: expected shape (..., 4), got {arr.shape}")
    return arr


# --- vectors -------------------------------------------------------------------------------------


def ned_from_enu(v_enu: ArrayLike) -> FloatArray:
    """World vector(s) ENU -> NED: (e, n, u) -> (n, e, -u). Positions, velocities, accelerations."""
    v = _vectors(v_enu, "v_enu")
    return v @ P_NED_ENU.T


def enu_from_ned(v_ned: ArrayLike) -> FloatArray:
    """World vector(s) NED -> ENU: (n, e, d) -> (e, n, -d)."""
    v = _vectors(v_ned, "v_ned")
    return v @ P_NED_ENU.T


def frd_from_flu(v_flu: ArrayLike) -> FloatArray:
    """Body vector(s) FLU -> FRD: (x, y, z) -> (x, -y, -z). Rates, torques, specific forces."""
    v = _vectors(v_flu, "v_flu")
    return v @ F_FRD_FLU.T


def flu_from_frd(v_frd: ArrayLike) -> FloatArray:
    """Body vector(s) FRD -> FLU: (x, y, z) -> (x, -y, -z)."""
    v = _vectors(v_frd, "v_frd")
    return v @ F_FRD_FLU.T


# --- headings ------------------------------------------------------------------------------------


def yaw_ned_from_enu(yaw_enu_rad: ArrayLike) -> FloatArray:
    """World yaw(s) ENU -> NED [rad]: from east, anticlockwise -> from north, clockwise
    (pi/2 - yaw), wrapped to [-pi, pi)."""
    yaw = np.asarray(yaw_enu_rad, dtype=float)
    return np.remainder(np.pi / 2.0 - yaw + np.pi, 2.0 * np.pi) - np.pi


# --- rotation matrices ---------------------------------------------------------------------------


def _signed_permutation(m: FloatArray) -> tuple[NDArray[np.intp], FloatArray]:
    """(idx, sign) of a signed permutation matrix: (m @ x)[i] = sign[i] * x[idx[i]]."""
    idx = np.abs(m).argmax(axis=1)
    return idx, m[np.arange(m.shape[0]), idx]


# P R F for a stack of R, as row and column picks with signs (P and F are signed permutations):
# (P R F)[i, j] = P_sign[i] F_sign[j] R[P_rows[i], F_cols[j]]; a stacked matmul costs ~5x more
_P_ROWS, _P_SIGN = _signed_permutation(P_NED_ENU)
_F_COLS, _F_SIGN = _signed_permutation(F_FRD_FLU.T)
_PF_SIGN = _P_SIGN[:, None] * _F_SIGN[None, :]


def _p_r_f(r: FloatArray) -> FloatArray:
    return r[..., _P_ROWS, :][..., _F_COLS] * _PF_SIGN


def rotation_ned_frd_from_enu_flu(rotation_enu_flu: ArrayLike) -> FloatArray:
    """Attitude(s) R_enu_flu (body FLU -> ENU) -> R_ned_frd (body FRD -> NED) = P R F."""
    return _p_r_f(_matrices(rotation_enu_flu, "rotation_enu_flu"))


def rotation_enu_flu_from_ned_frd(rotation_ned_frd: ArrayLike) -> FloatArray:
    """Attitude(s) R_ned_frd (body FRD -> NED) -> R_enu_flu (body FLU -> ENU) = P R F."""
    return _p_r_f(_matrices(rotation_ned_frd, "rotation_ned_frd"))


def is_rotation(rotation: ArrayLike, tol: float = 1e-6) -> NDArray[np.bool_]:
    """True where a (..., 3, 3) matrix is finite, orthonormal and has determinant +1 within tol."""
    r = _matrices(rotation, "rotation")
    finite = np.all(np.isfinite(r), axis=(-2, -1))
    r_safe = np.where(finite[..., None, None], r, 0.0)
    gram = np.swapaxes(r_safe, -1, -2) @ r_safe
    ortho = np.max(np.abs(gram - np.eye(3)), axis=(-2, -1)) <= tol
    det_ok = np.abs(np.linalg.det(r_safe) - 1.0) <= tol
    return finite & ortho & det_ok


# --- quaternions (Hamilton, w x y z) -------------------------------------------------------------


def rotation_from_quat_wxyz(q_wxyz: ArrayLike) -> FloatArray:
    """Rotation matrix/matrices of Hamilton quaternion(s) (w, x, y, z); normalises; zero raises."""
    q = _quaternions(q_wxyz, "q_wxyz")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(norm)) or np.any(norm < 1e-9):
        raise ValueError(f"q_wxyz: expected finite non-zero quaternions, norms {norm.ravel()}")
    w, x, y, z = np.moveaxis(q / norm, -1, 0)
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    r[..., 0, 1] = 2.0 * (x * y - w * z)
    r[..., 0, 2] = 2.0 * (x * z + w * y)
    r[..., 1, 0] = 2.0 * (x * y + w * z)
    r[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    r[..., 1, 2] = 2.0 * (y * z - w * x)
    r[..., 2, 0] = 2.0 * (x * z - w * y)
    r[..., 2, 1] = 2.0 * (y * z + w * x)
    r[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return r


def quat_wxyz_from_rotation(rotation: ArrayLike) -> FloatArray:
    """Unit quaternion(s) (w, x, y, z), w >= 0, of rotation matrices (Shepperd's method)."""
    r = _matrices(rotation, "rotation")
    lead = r.shape[:-2]
    m = r.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    case = np.argmax(np.stack([trace, m00, m11, m22], axis=-1), axis=-1)
    q = np.empty((m.shape[0], 4))
    # Each case divides by its own largest component, so it never divides by (nearly) zero.
    for k, diag in enumerate((trace, 1.0 + m00 - m11 - m22, 1.0 - m00 + m11 - m22,
                              1.0 - m00 - m11 + m22)):
        sel = case == k
        if not np.any(sel):
            continue
        s = m[sel]
        big = 0.5 * np.sqrt(np.maximum(diag[sel] + (1.0 if k == 0 else 0.0), 0.0))
        f = 0.25 / big
        d21, d02, d10 = s[:, 2, 1] - s[:, 1, 2], s[:, 0, 2] - s[:, 2, 0], s[:, 1, 0] - s[:, 0, 1]
        s01, s02, s12 = s[:, 0, 1] + s[:, 1, 0], s[:, 0, 2] + s[:, 2, 0], s[:, 1, 2] + s[:, 2, 1]
        if k == 0:
            q[sel] = np.stack([big, d21 * f, d02 * f, d10 * f], axis=-1)
        elif k == 1:
            q[sel] = np.stack([d21 * f, big, s01 * f, s02 * f], axis=-1)
        elif k == 2:
            q[sel] = np.stack([d02 * f, s01 * f, big, s12 * f], axis=-1)
        else:
            q[sel] = np.stack([d10 * f, s02 * f, s12 * f, big], axis=-1)
    q = np.where(q[:, :1] < 0.0, -q, q)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(lead + (4,))


def quat_xyzw_from_wxyz(q_wxyz: ArrayLike) -> FloatArray:
    """Reorder quaternion(s) (w, x, y, z) -> (x, y, z, w) (scipy's order)."""
    q = _quaternions(q_wxyz, "q_wxyz")
    return np.roll(q, -1, axis=-1)


def quat_wxyz_from_xyzw(q_xyzw: ArrayLike) -> FloatArray:
    """Reorder quaternion(s) (x, y, z, w) -> (w, x, y, z) (MAVLink's order)."""
    q = _quaternions(q_xyzw, "q_xyzw")
    return np.roll(q, 1, axis=-1)


# --- MAVLink attitude <-> app attitude -----------------------------------------------------------


def mavlink_quat_from_rotation_enu_flu(rotation_enu_flu: ArrayLike) -> FloatArray:
    """MAVLink quaternion(s) (w, x, y, z) of R_ned_frd from app attitude(s) R_enu_flu."""
    return quat_wxyz_from_rotation(rotation_ned_frd_from_enu_flu(rotation_enu_flu))


def rotation_enu_flu_from_mavlink_quat(q_ned_frd_wxyz: ArrayLike) -> FloatArray:
    """App attitude(s) R_enu_flu from MAVLink quaternion(s) (w, x, y, z) of R_ned_frd."""
    return rotation_enu_flu_from_ned_frd(rotation_from_quat_wxyz(q_ned_frd_wxyz))


def rotation_ned_frd_from_euler(roll_rad: ArrayLike, pitch_rad: ArrayLike,
                                yaw_rad: ArrayLike) -> FloatArray:
    """R_ned_frd = Rz(yaw) Ry(pitch) Rx(roll) from MAVLink ATTITUDE angles (rad); broadcasts."""
    phi, theta, psi = np.broadcast_arrays(np.asarray(roll_rad, dtype=np.float64),
                                          np.asarray(pitch_rad, dtype=np.float64),
                                          np.asarray(yaw_rad, dtype=np.float64))
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    r = np.empty(phi.shape + (3, 3))
    r[..., 0, 0] = ct * cp
    r[..., 0, 1] = sf * st * cp - cf * sp
    r[..., 0, 2] = cf * st * cp + sf * sp
    r[..., 1, 0] = ct * sp
    r[..., 1, 1] = sf * st * sp + cf * cp
    r[..., 1, 2] = cf * st * sp - sf * cp
    r[..., 2, 0] = -st
    r[..., 2, 1] = sf * ct
    r[..., 2, 2] = cf * ct
    return r


def rotation_enu_flu_from_mavlink_euler(roll_rad: ArrayLike, pitch_rad: ArrayLike,
                                        yaw_rad: ArrayLike) -> FloatArray:
    """App attitude(s) R_enu_flu from MAVLink ATTITUDE roll/pitch/yaw (rad, FRD w.r.t. NED)."""
    return rotation_enu_flu_from_ned_frd(rotation_ned_frd_from_euler(roll_rad, pitch_rad, yaw_rad))
