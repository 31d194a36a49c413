"""Position loop: command force (23) with tanh saturation, I&I mass estimator (24), thrust (12).

All vectors are world ENU (z up). Batched over the team: p, v (n, 3); the graph enters as an
edge list `graph` (formation.EdgeList: row i's neighbours j and weights a_ij) and the offsets
theta_i (n, 3), so row i reads only its own state and its neighbours' (a_ij != 0), and a tick
costs O(n + m) for m edges. `reference` is (4, 3): v_r and its first three time derivatives (see
formation.reference_velocity).

Saturation: sat(x) = sigma_a tanh(x / sigma_a), dsat = 1 - tanh^2(x / sigma_a),
ddsat = -(2 / sigma_a) tanh(x / sigma_a) dsat (sigma_a = 1 in the paper).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from gcs.control.formation import EdgeList, reference_velocity
from gcs.control.gains import LawGains


class PositionStage(NamedTuple):
    """The position stage's outputs for the team (gcs.control.law.position_stage), world ENU:
    the command force u (23), its a, s, ve, phi, kappa = alpha_m mhat / phi, the thrust
    T = |u| (12) and mhat' (24) (zero for the baseline)."""

    force_n: np.ndarray
    accel_cmd: np.ndarray
    s: np.ndarray
    ve: np.ndarray
    phi: np.ndarray
    kappa: np.ndarray
    thrust_n: np.ndarray
    mhat_rate: np.ndarray


@njit(cache=True)
def sat(x: float, sigma_a: float) -> float:
    return sigma_a * np.tanh(x / sigma_a)


@njit(cache=True)
def dsat(x: float, sigma_a: float) -> float:
    t = np.tanh(x / sigma_a)
    return 1.0 - t * t


@njit(cache=True)
def ddsat(x: float, sigma_a: float) -> float:
    t = np.tanh(x / sigma_a)
    return -2.0 / sigma_a * t * (1.0 - t * t)


@njit(cache=True)
def axis_weight(k: int, horizontal: float) -> float:
    """w_k of phi and zeta: `horizontal` for east and north, 1 for up."""
    return 1.0 if k == 2 else horizontal


@njit(cache=True)
def phi(velocity_mps: np.ndarray, sigma_a: float, horizontal: float = 1.0) -> np.ndarray:
    """phi_i = 2 + (1/(3 sigma_a)) sum_k w_k sat(v_i,k), uses the absolute velocity; w_k =
    `horizontal` (gains.phi_horizontal) for east and north, 1 for up. The paper's phi is w = 1,
    in (1, 3); any w in [0, 1] keeps phi in (1, 3) and the estimator's error dynamics (37)
    unchanged (mass_estimator_rate)."""
    n = velocity_mps.shape[0]
    out = np.empty(n)
    for i in range(n):
        acc = 0.0
        for k in range(3):
            acc += axis_weight(k, horizontal) * sat(velocity_mps[i, k], sigma_a)
        out[i] = 2.0 + acc / (3.0 * sigma_a)
    return out


@njit(cache=True)
def sliding_variable(
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    graph: EdgeList,
    offsets_m: np.ndarray,
    c_p: float,
    reference_mps: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """s_i of (21) and v_i^e = v_i - v_r, both (n, 3).

    s_i = c_p sum_j a_ij (p_i - p_j - theta_ij) + v_i^e with theta_ij = theta_i - theta_j,
    the sum over row i of the edge list (its neighbours j in ascending order, a_ij != 0).
    """
    n = position_m.shape[0]
    s = np.empty((n, 3))
    ve = np.empty((n, 3))
    row_start, neighbour, weight = graph.row_start, graph.neighbour, graph.weight
    for i in range(n):
        for k in range(3):
            coupling = 0.0
            for e in range(row_start[i], row_start[i + 1]):
                a = weight[e]
                if a != 0.0:
                    j = neighbour[e]
                    coupling += a * (
                        position_m[i, k] - offsets_m[i, k] - position_m[j, k] + offsets_m[j, k]
                    )
            ve[i, k] = velocity_mps[i, k] - reference_mps[0, k]
            s[i, k] = c_p * coupling + ve[i, k]
    return s, ve


@njit(cache=True)
def saturated_samples(
    t_s: np.ndarray,
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    graph: EdgeList,
    offsets_m: np.ndarray,
    gains: tuple[float, float],
    reference: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> int:
    """How many (sample, vehicle) pairs of a log (T, n, 3) have a saturated term of the force
    (23) past its knee: |s_ik| or |v^e_ik| >= sigma_a for some axis k, with s and v^e of (21)
    at each sample's time. gains = (c_p, sigma_a); reference as formation.reference_velocity."""
    c_p, sigma_a = gains
    constant, amplitude, omega, phase = reference
    hits = 0
    for m in range(t_s.size):
        ref = reference_velocity(t_s[m], constant, amplitude, omega, phase)
        s, ve = sliding_variable(position_m[m], velocity_mps[m], graph, offsets_m, c_p, ref)
        for i in range(s.shape[0]):
            for k in range(3):
                if abs(s[i, k]) >= sigma_a or abs(ve[i, k]) >= sigma_a:
                    hits += 1
                    break
    return hits


@njit(cache=True)
def force_law(
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    mhat: np.ndarray,
    nominal_mass_kg: np.ndarray,
    graph: EdgeList,
    offsets_m: np.ndarray,
    reference_mps: np.ndarray,
    gains: LawGains,
    adaptive: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Command force u_i (23) [N, ENU] for the team, with the terms later stages reuse.

    u_i = kappa_i a_i,  a_i = -alpha_p (sat(s_i) + sat(v_i^e)) + g e3 + v_r',
    kappa_i = alpha_m mhat_i / phi_i (adaptive) or the nominal mass m_i (the non-adaptive
    baseline of Scenario II, which ignores mhat). kappa_i is the law's current mass estimate.

    Returns (u, a, s, ve, phi, kappa) shaped (n,3), (n,3), (n,3), (n,3), (n,), (n,).
    """
    sig = gains.sigma_a
    s, ve = sliding_variable(
        position_m, velocity_mps, graph, offsets_m, gains.c_p, reference_mps
    )
    ph = phi(velocity_mps, sig, gains.phi_horizontal)
    n = position_m.shape[0]
    kappa = np.empty(n)
    a = np.empty((n, 3))
    u = np.empty((n, 3))
    for i in range(n):
        kappa[i] = gains.alpha_m * mhat[i] / ph[i] if adaptive else nominal_mass_kg[i]
        for k in range(3):
            a[i, k] = (
                -gains.alpha_p * (sat(s[i, k], sig) + sat(ve[i, k], sig)) + reference_mps[1, k]
            )
        a[i, 2] += gains.gravity_mps2
        for k in range(3):
            u[i, k] = kappa[i] * a[i, k]
    return u, a, s, ve, ph, kappa


@njit(cache=True)
def thrust(force_n: np.ndarray) -> np.ndarray:
    """Applied thrust T_i = |u_i| (12) [N]."""
    n = force_n.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = np.sqrt(force_n[i, 0] ** 2 + force_n[i, 1] ** 2 + force_n[i, 2] ** 2)
    return out


@njit(cache=True)
def mass_estimator_rate(
    velocity_mps: np.ndarray,
    rotation: np.ndarray,
    thrust_n: np.ndarray,
    mhat: np.ndarray,
    phi_values: np.ndarray,
    gains: LawGains,
) -> np.ndarray:
    """I&I update mhat_i' of (24), with the sign corrected (docs/control-law.md, "Deviations").

    mhat' = -g dsat(v_z) mhat / (3 sigma_a phi) + T zeta^T R e3 / (3 sigma_a alpha_m),
    zeta_k = w_k dsat(v_k), the gradient of phi times 3 sigma_a (phi's weights w_k). Needs no
    acceleration: with m v' = T R e3 - m g e3 the error mt = alpha_m mhat - phi m obeys
    mt' = -g dsat(v_z) mt / (3 sigma_a phi) whatever w, so alpha_m mhat/phi -> m exponentially.
    With w = 0 on east and north the update reads the thrust's vertical share alone: an error
    of the read tilt enters at second order, the horizontal velocity's error not at all.
    """
    sig = gains.sigma_a
    n = velocity_mps.shape[0]
    out = np.empty(n)
    for i in range(n):
        zeta_re3 = 0.0
        for k in range(3):
            zeta_re3 += (axis_weight(k, gains.phi_horizontal) * dsat(velocity_mps[i, k], sig)
                         * rotation[i, k, 2])
        out[i] = -gains.gravity_mps2 * dsat(velocity_mps[i, 2], sig) * mhat[i] / (
            3.0 * sig * phi_values[i]
        ) + thrust_n[i] * zeta_re3 / (3.0 * sig * gains.alpha_m)
    return out
