"""Time derivatives u', u'' of the command force: model-based closed form and Levant's (28).

The command angular velocity (docs/control-law.md) needs u' and u''. Two ways to get them:

* `force_derivatives`: differentiate (23) analytically along the closed loop. It needs
  each vehicle's acceleration v' (measured: specific force rotated to world minus g e3; in the
  test oracle, the model with the true mass), its neighbours' accelerations (their telemetry), and
  a gain k_i with v_i'' = k_i (T_i' R_i e3 + T_i R_i (omega_i x e3)): k_i = 1/m_i gives the exact
  oracle, k_i = 1/kappa_i (the law's own mass estimate) the implementable model-based method.
* `levant_advance`: the paper's robust exact differentiator (28) run on the sampled u with
  explicit-Euler substeps, for comparison (it needs L >= 1e3 and substeps <= 1e-4 s:
  docs/control-law.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from gcs.control.formation import EdgeList
from gcs.control.gains import LawGains
from gcs.control.position import PositionStage, axis_weight, ddsat, dsat

if TYPE_CHECKING:
    from gcs.control.law import TeamMeasurement


@njit(cache=True)
def force_derivatives(
    meas: TeamMeasurement,
    stage: PositionStage,
    mhat: np.ndarray,
    jerk_gain: np.ndarray,
    graph: EdgeList,
    reference_mps: np.ndarray,
    gains: LawGains,
    adaptive: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """u' and u'' (n, 3) of the command force u = kappa a (23), given v' of every vehicle.

    ``meas`` (gcs.control.law.TeamMeasurement) gives v, v' (its acceleration), R and omega; its
    position is not read. ``stage`` is position_stage's output (position.PositionStage: u, a, s,
    ve, phi, kappa from position.force_law, mhat' from position.mass_estimator_rate); omega is
    body FLU, everything else world ENU.
    With the baseline (adaptive=False) kappa is constant, so kappa' = kappa'' = 0. The graph
    terms s' and s'' sum over row i of the edge list, as s does in position.sliding_variable.
    """
    velocity_mps = meas.velocity_mps
    acceleration_mps2 = meas.acceleration_mps2
    rotation = meas.rotation
    omega_radps = meas.omega_radps
    force_n, accel_cmd, s, ve, phi_values, kappa, _thrust, mhat_rate = stage
    n = velocity_mps.shape[0]
    row_start, neighbour, weight = graph.row_start, graph.neighbour, graph.weight
    sig = gains.sigma_a
    g = gains.gravity_mps2
    am = gains.alpha_m
    ap = gains.alpha_p
    du = np.empty((n, 3))
    ddu = np.empty((n, 3))
    a_d = np.empty(3)
    ve_d = np.empty(3)
    s_d = np.empty(3)
    v_dd = np.empty(3)
    w = np.empty(3)  # phi's axis weights (position.phi)
    for k in range(3):
        w[k] = axis_weight(k, gains.phi_horizontal)
    for i in range(n):
        # First derivatives: ve', s', phi', kappa', a', u'.
        phi_i = phi_values[i]
        phi_d = 0.0
        for k in range(3):
            coupling_d = 0.0
            for e in range(row_start[i], row_start[i + 1]):
                aij = weight[e]
                if aij != 0.0:
                    j = neighbour[e]
                    coupling_d += aij * (velocity_mps[i, k] - velocity_mps[j, k])
            ve_d[k] = acceleration_mps2[i, k] - reference_mps[1, k]
            s_d[k] = gains.c_p * coupling_d + ve_d[k]
            phi_d += w[k] * dsat(velocity_mps[i, k], sig) * acceleration_mps2[i, k]
        phi_d /= 3.0 * sig
        if adaptive:
            kap_d = am * (mhat_rate[i] / phi_i - mhat[i] * phi_d / phi_i**2)
        else:
            kap_d = 0.0
        for k in range(3):
            a_d[k] = (
                -ap * (dsat(s[i, k], sig) * s_d[k] + dsat(ve[i, k], sig) * ve_d[k])
                + reference_mps[2, k]
            )
            du[i, k] = kap_d * accel_cmd[i, k] + kappa[i] * a_d[k]
        # Thrust rate and jerk: v'' = k (T' R e3 + T R (omega x e3)).
        t_n = math.sqrt(force_n[i, 0] ** 2 + force_n[i, 1] ** 2 + force_n[i, 2] ** 2)
        t_d = (force_n[i, 0] * du[i, 0] + force_n[i, 1] * du[i, 1] + force_n[i, 2] * du[i, 2]) / t_n
        wx = omega_radps[i, 0]
        wy = omega_radps[i, 1]
        zeta_re3 = 0.0
        zeta_d_re3 = 0.0
        zeta_rwe3 = 0.0
        for k in range(3):
            re3 = rotation[i, k, 2]
            rwe3 = rotation[i, k, 0] * wy - rotation[i, k, 1] * wx  # R (omega x e3)
            v_dd[k] = jerk_gain[i] * (t_d * re3 + t_n * rwe3)
            zeta = w[k] * dsat(velocity_mps[i, k], sig)
            zeta_d = w[k] * ddsat(velocity_mps[i, k], sig) * acceleration_mps2[i, k]
            zeta_re3 += zeta * re3
            zeta_d_re3 += zeta_d * re3
            zeta_rwe3 += zeta * rwe3
        # Second derivatives: phi'', mhat'', kappa'', a'', u''.
        phi_dd = 0.0
        for k in range(3):
            phi_dd += w[k] * (
                ddsat(velocity_mps[i, k], sig) * acceleration_mps2[i, k] ** 2
                + dsat(velocity_mps[i, k], sig) * v_dd[k]
            )
        phi_dd /= 3.0 * sig
        if adaptive:
            zeta_z = dsat(velocity_mps[i, 2], sig)
            zeta_dz = ddsat(velocity_mps[i, 2], sig) * acceleration_mps2[i, 2]
            mhat_dd = -(g / (3.0 * sig)) * (
                zeta_dz * mhat[i] / phi_i
                + zeta_z * mhat_rate[i] / phi_i
                - zeta_z * mhat[i] * phi_d / phi_i**2
            ) + (t_d * zeta_re3 + t_n * zeta_d_re3 + t_n * zeta_rwe3) / (3.0 * sig * am)
            kap_dd = am * (
                mhat_dd / phi_i
                - 2.0 * mhat_rate[i] * phi_d / phi_i**2
                - mhat[i] * phi_dd / phi_i**2
                + 2.0 * mhat[i] * phi_d**2 / phi_i**3
            )
        else:
            kap_dd = 0.0
        for k in range(3):
            coupling_dd = 0.0
            for e in range(row_start[i], row_start[i + 1]):
                aij = weight[e]
                if aij != 0.0:
                    j = neighbour[e]
                    coupling_dd += aij * (acceleration_mps2[i, k] - acceleration_mps2[j, k])
            ve_dd = v_dd[k] - reference_mps[2, k]
            s_dd = gains.c_p * coupling_dd + ve_dd
            a_dd = (
                -ap
                * (
                    ddsat(s[i, k], sig) * s_d[k] ** 2
                    + dsat(s[i, k], sig) * s_dd
                    + ddsat(ve[i, k], sig) * ve_d[k] ** 2
                    + dsat(ve[i, k], sig) * ve_dd
                )
                + reference_mps[3, k]
            )
            ddu[i, k] = kap_dd * accel_cmd[i, k] + 2.0 * kap_d * a_d[k] + kappa[i] * a_dd
    return du, ddu


@njit(cache=True)
def levant_gains(lipschitz: float) -> tuple[float, float, float]:
    """(lambda0, lambda1, lambda2) = (3 L^(1/3), 1.5 L^(1/2), 1.1 L) for L >= sup |u'''|."""
    return 3.0 * lipschitz ** (1.0 / 3.0), 1.5 * math.sqrt(lipschitz), 1.1 * lipschitz


@njit(cache=True)
def _sign(x: float) -> float:
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def levant_advance(
    state: np.ndarray,
    u_prev: np.ndarray,
    u_now: np.ndarray,
    duration_s: float,
    max_substep_s: float,
    lipschitz: float,
) -> None:
    """Advance Levant's second-order differentiator (28) over one sample interval, in place.

    `state` is (n, 3, 3): state[..., 0] = k0 (estimate of u), [..., 1] = k1 (u'),
    [..., 2] = k2 (u''), one differentiator per component of u. The input is interpolated
    linearly from u_prev to u_now over `duration_s`, integrated by explicit Euler with
    ceil(duration_s / max_substep_s) equal substeps. Initialise k0 = u(0), k1 = k2 = 0.
    """
    lam0, lam1, lam2 = levant_gains(lipschitz)
    nsub = max(1, int(math.ceil(duration_s / max_substep_s - 1e-9)))
    h = duration_s / nsub
    n = state.shape[0]
    for i in range(n):
        for k in range(3):
            k0 = state[i, k, 0]
            k1 = state[i, k, 1]
            k2 = state[i, k, 2]
            for step in range(nsub):
                frac = step / nsub
                u_in = u_prev[i, k] + (u_now[i, k] - u_prev[i, k]) * frac
                e0 = k0 - u_in
                d0 = -lam0 * abs(e0) ** (2.0 / 3.0) * _sign(e0) + k1
                e1 = k1 - d0
                d1 = -lam1 * math.sqrt(abs(e1)) * _sign(e1) + k2
                d2 = -lam2 * _sign(k2 - d1)
                k0 += h * d0
                k1 += h * d1
                k2 += h * d2
            state[i, k, 0] = k0
            state[i, k, 1] = k1
            state[i, k, 2] = k2
