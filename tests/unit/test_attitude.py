"""Attitude loop (19), (26), (27) and the corrected Lyapunov function (29)."""

from __future__ import annotations

import numpy as np
import pytest

from flightkit.physics import TABLE_I
from gcs.control.attitude import (
    adaptive_torque,
    attitude_errors,
    attitude_lyapunov,
    rate_command,
    regressor,
)
from gcs.control.gains import PAPER_GAINS
from gcs.control.geometry import command_angular_velocity, command_attitude, hat


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("seed", range(10))
def test_regressor_identity(seed):
    # GIVEN a random attitude, command attitude and rates, and an inertia J
    rng = np.random.default_rng(seed)
    rot, rc = _random_rotation(rng)[None], _random_rotation(rng)[None]
    omega, wc, dwc = rng.normal(size=(3, 1, 3))
    j = rng.uniform(0.02, 0.7, size=3)
    re, eps, tr_err, wc_body, we = attitude_errors(rot, rc, omega, wc)
    # WHEN the regressor of (19) is formed
    gam = regressor(re, omega, wc, dwc, we, wc_body)[0]
    # THEN Gamma rho = -omega x J omega + J varpi with varpi = w^e x (R^eT w^c) - R^eT w^c'
    varpi = np.cross(we[0], re[0].T @ wc[0]) - re[0].T @ dwc[0]
    expected = -np.cross(omega[0], j * omega[0]) + j * varpi
    assert np.allclose(gam @ j, expected, atol=1e-14)


@pytest.mark.parametrize("seed", range(5))
def test_error_kinematics_16_and_17(seed):
    # GIVEN R(t) = R0 exp(t w^) and a constant R^c WHEN the errors are differentiated numerically
    rng = np.random.default_rng(100 + seed)
    r0, rc = _random_rotation(rng), _random_rotation(rng)
    w = rng.normal(size=3)

    def errors(t):
        from scipy.linalg import expm

        rot = (r0 @ expm(t * hat(w)))[None]
        return attitude_errors(rot, rc[None], w[None], np.zeros((1, 3)))

    h = 1e-5
    re, eps, tr_err, _, we = errors(0.0)
    d_tr = (errors(h)[2] - errors(-h)[2]) / (2 * h)
    d_eps = (errors(h)[1] - errors(-h)[1]) / (2 * h)
    # THEN d/dt tr(I - R^e) = eps^T w^e (16) and eps' = (tr(R^e) I - R^eT) w^e (17, corrected)
    assert d_tr[0] == pytest.approx(eps[0] @ we[0], abs=1e-8)
    omega_mat = np.trace(re[0]) * np.eye(3) - re[0].T
    assert np.allclose(d_eps[0], omega_mat @ we[0], atol=1e-8)
    # AND the paper's printed Omega (without the transpose) does not fit in general
    wrong = np.trace(re[0]) * np.eye(3) - re[0]
    assert not np.allclose(d_eps[0], wrong @ we[0], atol=1e-6)


def _attitude_only_run(inertia, seconds=6.0, dt=2e-4):
    """Single body under (26)+(27) tracking R^c(u(t)) for a smooth u(t); returns L(t) of (29)."""
    gains = PAPER_GAINS

    def force(t, order):
        c = np.array([1.5, -1.0, 0.0])
        w = np.array([1.3, 0.7, 0.0])
        base = np.array([0.0, 0.0, 9.0])
        if order == 0:
            return (base + c * np.sin(w * t))[None]
        if order == 1:
            return (c * w * np.cos(w * t))[None]
        return (-c * w * w * np.sin(w * t))[None]

    j = np.array(inertia)

    def rates(t, rot, omega, rhohat):
        u = force(t, 0)
        rc = command_attitude(u)
        wc, dwc = command_angular_velocity(u, force(t, 1), force(t, 2), rc)
        re, eps, tr_err, wc_body, we = attitude_errors(rot[None], rc, omega[None], wc)
        gam = regressor(re, omega[None], wc, dwc, we, wc_body)
        tau, rho_rate = adaptive_torque(eps, tr_err, we, gam, rhohat[None], gains, True)
        lyap = attitude_lyapunov(tr_err, eps, we, j[None], (j - rhohat)[None], gains)[0]
        domega = (tau[0] - np.cross(omega, j * omega)) / j
        return rot @ hat(omega), domega, rho_rate[0], lyap

    rot = np.array([[1.0, 0, 0], [0, np.cos(0.5), -np.sin(0.5)], [0, np.sin(0.5), np.cos(0.5)]])
    omega = np.array([0.5, -0.3, 0.2])
    rhohat = np.full(3, 0.08)
    values = []
    t = 0.0
    while t < seconds:
        k1 = rates(t, rot, omega, rhohat)
        values.append(k1[3])
        k2 = rates(
            t + dt / 2, rot + dt / 2 * k1[0], omega + dt / 2 * k1[1], rhohat + dt / 2 * k1[2]
        )
        k3 = rates(
            t + dt / 2, rot + dt / 2 * k2[0], omega + dt / 2 * k2[1], rhohat + dt / 2 * k2[2]
        )
        k4 = rates(t + dt, rot + dt * k3[0], omega + dt * k3[1], rhohat + dt * k3[2])
        rot = rot + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        u_, _, vt = np.linalg.svd(rot)
        rot = u_ @ vt
        omega = omega + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        rhohat = rhohat + dt / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        t += dt
    return np.array(values)


@pytest.mark.slow
def test_corrected_lyapunov_function_decreases_along_an_attitude_only_run():
    # GIVEN UAV 3 (the stiffest) under the adaptive torque law, tracking a moving command attitude
    lyap = _attitude_only_run(TABLE_I[2].inertia_kgm2, seconds=3.0)
    # THEN the corrected (29) decreases monotonically (up to integration round-off) to near zero
    assert lyap[0] > 1.0
    assert np.max(np.diff(lyap)) < 1e-8
    assert lyap[-1] < 0.05 * lyap[0]


def test_torque_is_pure_feedback_at_zero_error_and_rate_command_feeds_forward():
    # GIVEN R = R^c and omega = R^eT omega^c with zero regressor terms
    rot = np.eye(3)[None]
    wc = np.zeros((1, 3))
    re, eps, tr_err, wc_body, we = attitude_errors(rot, rot, wc, wc)
    gam = regressor(re, wc, wc, wc, we, wc_body)
    tau, rho_rate = adaptive_torque(eps, tr_err, we, gam, np.full((1, 3), 0.08), PAPER_GAINS, True)
    # THEN the torque and the adaptation vanish
    assert np.allclose(tau, 0.0) and np.allclose(rho_rate, 0.0)
    # AND the rate command of a small roll error rotates back (sign) at 2 k_eps
    small = np.array(
        [[1.0, 0, 0], [0, np.cos(0.01), -np.sin(0.01)], [0, np.sin(0.01), np.cos(0.01)]]
    )
    re, eps, tr_err, wc_body, we = attitude_errors(small[None], rot, np.zeros((1, 3)), wc)
    cmd = rate_command(eps, wc_body, PAPER_GAINS.k_eps, PAPER_GAINS.k_eps_yaw)
    assert cmd[0, 0] == pytest.approx(-2 * PAPER_GAINS.k_eps * 0.01, rel=1e-3)
    assert eps[0, 0] == pytest.approx(2 * np.sin(0.01))  # eps is not halved
