"""SO(3) geometry of the law: hat/vee, the command attitude (14) and its body rates.

Frames: world ENU (z up, e3 = [0, 0, 1]), body FLU; a rotation maps body to world. Every function
here is pure and compiled with numba; the batched ones take arrays shaped (n, 3) / (n, 3, 3) and
compute the whole team in one call.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Smallest admissible 1 + b_z of the unit command force direction b = u/|u| (eq. (14) is singular
#: at b = -e3). 1e-9 corresponds to a command force pointing within ~2.6e-3 deg of straight down.
NONSINGULAR_MARGIN = 1e-9


@njit(cache=True)
def hat(v: np.ndarray) -> np.ndarray:
    """Skew matrix of a 3-vector: hat(v) @ y == cross(v, y)."""
    out = np.zeros((3, 3))
    out[0, 1] = -v[2]
    out[0, 2] = v[1]
    out[1, 0] = v[2]
    out[1, 2] = -v[0]
    out[2, 0] = -v[1]
    out[2, 1] = v[0]
    return out


@njit(cache=True)
def vee(m: np.ndarray) -> np.ndarray:
    """Inverse of hat for the skew part: vee(hat(v)) == v (reads m[2,1], m[0,2], m[1,0])."""
    out = np.empty(3)
    out[0] = m[2, 1]
    out[1] = m[0, 2]
    out[2] = m[1, 0]
    return out


@njit(cache=True)
def is_nonsingular(force_n: np.ndarray) -> np.ndarray:
    """Per vehicle: does the command force (n, 3) admit the command attitude (14)?

    (14) needs u outside {(0, 0, u_z): u_z <= 0}; numerically, |u| > 0 and 1 + u_z/|u| above
    NONSINGULAR_MARGIN.
    """
    n = force_n.shape[0]
    ok = np.empty(n, dtype=np.bool_)
    for i in range(n):
        norm = np.sqrt(force_n[i, 0] ** 2 + force_n[i, 1] ** 2 + force_n[i, 2] ** 2)
        ok[i] = norm > 0.0 and 1.0 + force_n[i, 2] / norm > NONSINGULAR_MARGIN
    return ok


@njit(cache=True)
def command_attitude(force_n: np.ndarray) -> np.ndarray:
    """Command attitude R^c (n, 3, 3) of eq. (14): the minimal rotation taking e3 to u/|u|.

    R^c = I + k^ + (k^)^2 / (1 + b_z) with b = u/|u|, k = e3 x b (with the (2,2) entry corrected:
    docs/control-law.md, "Deviations from the paper"). The caller checks `is_nonsingular` first;
    a singular force gives non-finite output.
    """
    n = force_n.shape[0]
    rc = np.empty((n, 3, 3))
    for i in range(n):
        norm = np.sqrt(force_n[i, 0] ** 2 + force_n[i, 1] ** 2 + force_n[i, 2] ** 2)
        b1 = force_n[i, 0] / norm
        b2 = force_n[i, 1] / norm
        b3 = force_n[i, 2] / norm
        c = 1.0 + b3
        rc[i, 0, 0] = b3 + b2 * b2 / c
        rc[i, 0, 1] = -b1 * b2 / c
        rc[i, 0, 2] = b1
        rc[i, 1, 0] = -b1 * b2 / c
        rc[i, 1, 1] = b3 + b1 * b1 / c
        rc[i, 1, 2] = b2
        rc[i, 2, 0] = -b1
        rc[i, 2, 1] = -b2
        rc[i, 2, 2] = b3
    return rc


@njit(cache=True)
def command_angular_velocity(
    force_n: np.ndarray, dforce: np.ndarray, ddforce: np.ndarray, rc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Body rate omega^c of R^c and its time derivative, both (n, 3), from u, u', u''.

    (omega^c)^ = R^cT dR^c/dt. Closed forms, replacing the paper's Appendix (which is wrong as
    printed): with n = |u|, r1 = R^c e1, r2 = R^c e2, D = n (n + u_z),
      omega_x = -r2.u'/n,  omega_y = r1.u'/n,  omega_z = (u_y u_x' - u_x u_y')/D,
      omega'_x = (-r2.u'' - 2 n' omega_x)/n + omega_y omega_z,
      omega'_y = ( r1.u'' - 2 n' omega_y)/n - omega_x omega_z,
      omega'_z = (u_y u_x'' - u_x u_y'' - omega_z D')/D,  D' = n'(2n + u_z) + n u_z'.
    """
    count = force_n.shape[0]
    wc = np.empty((count, 3))
    dwc = np.empty((count, 3))
    for i in range(count):
        ux, uy, uz = force_n[i, 0], force_n[i, 1], force_n[i, 2]
        dx, dy, dz = dforce[i, 0], dforce[i, 1], dforce[i, 2]
        ddx, ddy, ddz = ddforce[i, 0], ddforce[i, 1], ddforce[i, 2]
        nrm = np.sqrt(ux * ux + uy * uy + uz * uz)
        dnrm = (ux * dx + uy * dy + uz * dz) / nrm
        den = nrm * (nrm + uz)
        dden = dnrm * (2.0 * nrm + uz) + nrm * dz
        r1_du = rc[i, 0, 0] * dx + rc[i, 1, 0] * dy + rc[i, 2, 0] * dz
        r2_du = rc[i, 0, 1] * dx + rc[i, 1, 1] * dy + rc[i, 2, 1] * dz
        r1_ddu = rc[i, 0, 0] * ddx + rc[i, 1, 0] * ddy + rc[i, 2, 0] * ddz
        r2_ddu = rc[i, 0, 1] * ddx + rc[i, 1, 1] * ddy + rc[i, 2, 1] * ddz
        wx = -r2_du / nrm
        wy = r1_du / nrm
        wz = (uy * dx - ux * dy) / den
        wc[i, 0] = wx
        wc[i, 1] = wy
        wc[i, 2] = wz
        dwc[i, 0] = (-r2_ddu - 2.0 * dnrm * wx) / nrm + wy * wz
        dwc[i, 1] = (r1_ddu - 2.0 * dnrm * wy) / nrm - wx * wz
        dwc[i, 2] = (uy * ddx - ux * ddy - wz * dden) / den
    return wc, dwc


@njit(cache=True)
def rotation_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Body-to-world rotation Rz(yaw) Ry(pitch) Rx(roll) (ZYX Euler angles, ENU/FLU)."""
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    r = np.empty((3, 3))
    r[0, 0] = cy * cp
    r[0, 1] = cy * sp * sr - sy * cr
    r[0, 2] = cy * sp * cr + sy * sr
    r[1, 0] = sy * cp
    r[1, 1] = sy * sp * sr + cy * cr
    r[1, 2] = sy * sp * cr - cy * sr
    r[2, 0] = -sp
    r[2, 1] = cp * sr
    r[2, 2] = cp * cr
    return r


@njit(cache=True)
def turn_about_thrust_axis(
    rc: np.ndarray, wc: np.ndarray, dwc: np.ndarray, heading_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The command attitude turned about its own thrust axis: R^c Rz(psi_i) per vehicle, with
    its body rate Rz(psi)^T omega^c and rate derivative Rz(psi)^T omega^c' (psi constant).

    R^c Rz(psi) e3 = R^c e3, so the thrust direction, and with it the position loop, is
    unchanged; only the heading the attitude loop aims for moves (by psi, up to a second-order
    term in the tilt: the minimal rotation (14) has heading -b_x b_y / (1 + b_z)). psi = 0
    returns the inputs themselves (the paper's law)."""
    n = rc.shape[0]
    if not np.any(heading_rad != 0.0):
        return rc, wc, dwc
    rc2 = np.empty((n, 3, 3))
    wc2 = np.empty((n, 3))
    dwc2 = np.empty((n, 3))
    for i in range(n):
        c, s = np.cos(heading_rad[i]), np.sin(heading_rad[i])
        for r in range(3):
            rc2[i, r, 0] = c * rc[i, r, 0] + s * rc[i, r, 1]
            rc2[i, r, 1] = -s * rc[i, r, 0] + c * rc[i, r, 1]
            rc2[i, r, 2] = rc[i, r, 2]
        wc2[i, 0] = c * wc[i, 0] + s * wc[i, 1]
        wc2[i, 1] = -s * wc[i, 0] + c * wc[i, 1]
        wc2[i, 2] = wc[i, 2]
        dwc2[i, 0] = c * dwc[i, 0] + s * dwc[i, 1]
        dwc2[i, 1] = -s * dwc[i, 0] + c * dwc[i, 1]
        dwc2[i, 2] = dwc[i, 2]
    return rc2, wc2, dwc2
