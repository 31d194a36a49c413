"""Attitude loop: errors (15)-(17), regressor (19), adaptive torque (26), inertia update (27),
and the thrust + body-rate variant for autopilots that take rate setpoints (docs/control-law.md).

R is body-to-world (ENU/FLU); omega, omega^c, tau are body-frame vectors; R^c, omega^c, omega^c'
come from geometry.command_attitude / command_angular_velocity. Batched over the team.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from gcs.control.gains import LawGains


@njit(cache=True)
def attitude_errors(
    rotation: np.ndarray, rc: np.ndarray, omega_radps: np.ndarray, wc: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """R^e = R^cT R, eps = vee(R^e - R^eT) (not halved), tr(I - R^e) in [0, 4],
    R^eT omega^c (body), and omega^e = omega - R^eT omega^c.

    Returns (re (n,3,3), eps (n,3), tr_err (n,), wc_body (n,3), we (n,3)).
    """
    n = rotation.shape[0]
    re = np.empty((n, 3, 3))
    eps = np.empty((n, 3))
    tr_err = np.empty(n)
    wc_body = np.empty((n, 3))
    we = np.empty((n, 3))
    for i in range(n):
        for r in range(3):
            for c in range(3):
                re[i, r, c] = (
                    rc[i, 0, r] * rotation[i, 0, c]
                    + rc[i, 1, r] * rotation[i, 1, c]
                    + rc[i, 2, r] * rotation[i, 2, c]
                )
        eps[i, 0] = re[i, 2, 1] - re[i, 1, 2]
        eps[i, 1] = re[i, 0, 2] - re[i, 2, 0]
        eps[i, 2] = re[i, 1, 0] - re[i, 0, 1]
        tr_err[i] = 3.0 - (re[i, 0, 0] + re[i, 1, 1] + re[i, 2, 2])
        for r in range(3):
            wc_body[i, r] = re[i, 0, r] * wc[i, 0] + re[i, 1, r] * wc[i, 1] + re[i, 2, r] * wc[i, 2]
            we[i, r] = omega_radps[i, r] - wc_body[i, r]
    return re, eps, tr_err, wc_body, we


@njit(cache=True)
def regressor(
    re: np.ndarray,
    omega_radps: np.ndarray,
    wc: np.ndarray,
    dwc: np.ndarray,
    we: np.ndarray,
    wc_body: np.ndarray,
) -> np.ndarray:
    """Gamma_i of (19), (n, 3, 3), such that J omega^e' = tau + Gamma rho, rho = (Jx, Jy, Jz).

    varpi = omega^e x (R^eT omega^c) - R^eT omega^c'; w = the actual body rate omega.
    """
    n = re.shape[0]
    gam = np.empty((n, 3, 3))
    for i in range(n):
        wx, wy, wz = omega_radps[i, 0], omega_radps[i, 1], omega_radps[i, 2]
        ex, ey, ez = we[i, 0], we[i, 1], we[i, 2]
        bx, by, bz = wc_body[i, 0], wc_body[i, 1], wc_body[i, 2]
        dbx = re[i, 0, 0] * dwc[i, 0] + re[i, 1, 0] * dwc[i, 1] + re[i, 2, 0] * dwc[i, 2]
        dby = re[i, 0, 1] * dwc[i, 0] + re[i, 1, 1] * dwc[i, 1] + re[i, 2, 1] * dwc[i, 2]
        dbz = re[i, 0, 2] * dwc[i, 0] + re[i, 1, 2] * dwc[i, 1] + re[i, 2, 2] * dwc[i, 2]
        vpx = ey * bz - ez * by - dbx
        vpy = ez * bx - ex * bz - dby
        vpz = ex * by - ey * bx - dbz
        gam[i, 0, 0] = vpx
        gam[i, 0, 1] = wy * wz
        gam[i, 0, 2] = -wy * wz
        gam[i, 1, 0] = -wx * wz
        gam[i, 1, 1] = vpy
        gam[i, 1, 2] = wx * wz
        gam[i, 2, 0] = wx * wy
        gam[i, 2, 1] = -wx * wy
        gam[i, 2, 2] = vpz
    return gam


@njit(cache=True)
def adaptive_torque(
    eps: np.ndarray,
    tr_err: np.ndarray,
    we: np.ndarray,
    gam: np.ndarray,
    rhohat: np.ndarray,
    gains: LawGains,
    adaptive: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Torque (26) [N m, body] and inertia-estimate rate (27), both (n, 3).

    tau = -eps/(4 - tr(I-R^e)) - alpha_eps eps - alpha_omega omega^e - Gamma rhohat,
    rhohat' = alpha_rho Gamma^T (c_eps eps + omega^e); frozen (zero) when not adaptive.
    """
    n = eps.shape[0]
    tau = np.empty((n, 3))
    rho_rate = np.zeros((n, 3))
    for i in range(n):
        barrier = 1.0 / (4.0 - tr_err[i])
        for r in range(3):
            g_rho = (
                gam[i, r, 0] * rhohat[i, 0]
                + gam[i, r, 1] * rhohat[i, 1]
                + gam[i, r, 2] * rhohat[i, 2]
            )
            tau[i, r] = (
                -barrier * eps[i, r]
                - gains.alpha_eps * eps[i, r]
                - gains.alpha_omega * we[i, r]
                - g_rho
            )
        if adaptive:
            for c in range(3):
                acc = 0.0
                for r in range(3):
                    acc += gam[i, r, c] * (gains.c_eps * eps[i, r] + we[i, r])
                rho_rate[i, c] = gains.alpha_rho * acc
    return tau, rho_rate


@njit(cache=True)
def rate_command(eps: np.ndarray, wc_body: np.ndarray, k_eps: float,
                 k_eps_yaw: float) -> np.ndarray:
    """Body-rate setpoint (n, 3) [rad/s, FLU] for the thrust + body-rate mode (docs/control-law.md).

    omega_cmd = R^eT omega^c - k_eps eps: the command attitude's own rate as feed-forward plus
    attitude feedback (for small errors eps ~ 2 x rotation vector, so the error decays at 2 k_eps).
    The autopilot's rate loop tracks it; the inertia adaptation (27) has no role in this mode.
    The yaw axis has its own gain k_eps_yaw (an autopilot's yaw-rate loop is several times slower
    than its roll and pitch; gcs/control/cascade.py).
    """
    out = wc_body - k_eps * eps
    out[:, 2] = wc_body[:, 2] - k_eps_yaw * eps[:, 2]
    return out


@njit(cache=True)
def attitude_lyapunov(
    tr_err: np.ndarray,
    eps: np.ndarray,
    we: np.ndarray,
    inertia_kgm2: np.ndarray,
    rho_error: np.ndarray,
    gains: LawGains,
) -> np.ndarray:
    """The corrected Lyapunov function (29) per vehicle (analysis and tests; needs the true J):

    L = ln(4/(4 - tr(I-R^e))) + alpha_eps tr(I-R^e) + c_eps eps^T J omega^e
        + 1/2 omega^eT J omega^e + 1/(2 alpha_rho) |rho - rhohat|^2.
    """
    n = eps.shape[0]
    out = np.empty(n)
    for i in range(n):
        cross = 0.0
        kinetic = 0.0
        rho_sq = 0.0
        for k in range(3):
            cross += eps[i, k] * inertia_kgm2[i, k] * we[i, k]
            kinetic += we[i, k] * inertia_kgm2[i, k] * we[i, k]
            rho_sq += rho_error[i, k] ** 2
        out[i] = (
            np.log(4.0 / (4.0 - tr_err[i]))
            + gains.alpha_eps * tr_err[i]
            + gains.c_eps * cross
            + 0.5 * kinetic
            + rho_sq / (2.0 * gains.alpha_rho)
        )
    return out
