"""u', u'' of the command force: the closed form against finite differences along the closed loop,
and Levant's differentiator (28) on known signals."""

from __future__ import annotations

import numpy as np
import pytest

from flightkit.physics import TABLE_I, orthonormalise
from gcs.control.derivatives import levant_advance
from gcs.control.formation import adjacency_from_edges, edge_list
from gcs.control.gains import PAPER_GAINS
from gcs.sim.loop import LawInputs, OracleState, TeamState, _oracle_rates


def _levant_track(signal, d1, d2, t_end, dt, lipschitz, substep):
    state = np.zeros((1, 3, 3))
    state[0, :, 0] = signal(0.0)
    errors = []
    t = 0.0
    prev = signal(0.0)[None]
    while t < t_end - 1e-12:
        now = signal(t + dt)[None]
        levant_advance(state, prev, now, dt, substep, lipschitz)
        prev = now
        t += dt
        errors.append(
            (t, np.abs(state[0, :, 1] - d1(t)).max(), np.abs(state[0, :, 2] - d2(t)).max())
        )
    return np.array(errors)


def test_levant_recovers_derivatives_of_a_smooth_signal():
    # GIVEN u(t) = (sin 2t, 0.5 cos 3t, t^2/2) sampled at 1 kHz, with |u'''| <= 13.5
    def u(t):
        return np.array([np.sin(2 * t), 0.5 * np.cos(3 * t), 0.5 * t * t])

    def du(t):
        return np.array([2 * np.cos(2 * t), -1.5 * np.sin(3 * t), t])

    def ddu(t):
        return np.array([-4 * np.sin(2 * t), -4.5 * np.cos(3 * t), 1.0])

    # WHEN Levant's differentiator runs with L = 100 >= sup|u'''| and 1e-4 s substeps
    err = _levant_track(u, du, ddu, 4.0, 1e-3, 100.0, 1e-4)
    late = err[err[:, 0] > 2.0]
    # THEN after its finite-time transient u' and u'' are accurate
    assert late[:, 1].max() < 5e-3
    assert late[:, 2].max() < 0.15


def test_levant_needs_a_large_enough_lipschitz_constant():
    # GIVEN a fast signal with |u'''| ~ 3400 WHEN L is far too small THEN the estimate is poor,
    # and with L above sup|u'''| it is good (the paper's "fast enough differentiator" condition)
    def u(t):
        return np.full(3, np.sin(15 * t))

    def du(t):
        return np.full(3, 15 * np.cos(15 * t))

    def ddu(t):
        return np.full(3, -225 * np.sin(15 * t))

    bad = _levant_track(u, du, ddu, 3.0, 1e-3, 10.0, 1e-4)
    good = _levant_track(u, du, ddu, 3.0, 1e-3, 1e4, 1e-5)
    assert bad[bad[:, 0] > 2, 1].max() > 1.0
    assert good[good[:, 0] > 2, 1].max() < 0.2


def _scenario_state():
    masses = np.array([a.mass_kg for a in TABLE_I])
    inertia = np.array([a.inertia_kgm2 for a in TABLE_I])
    p = np.array([[4.0, 4, 9], [3, -4, 11], [-5, -4, 12], [-1, 3, 8]])
    rng = np.random.default_rng(7)
    v = rng.normal(scale=0.5, size=(4, 3))
    rot = np.empty((4, 3, 3))
    for i in range(4):
        q, r = np.linalg.qr(np.eye(3) + 0.2 * rng.normal(size=(3, 3)))
        q = q @ np.diag(np.sign(np.diag(r)))
        rot[i] = q if np.linalg.det(q) > 0 else -q
    w = rng.normal(scale=0.3, size=(4, 3))
    mhat = np.array([1.0, 4.0, 1.0, 4.0])
    rhohat = np.full((4, 3), 0.08)
    graph = edge_list(
        adjacency_from_edges(4, [(0, 1, 1.0), (1, 2, 1.0), (2, 3, 1.0), (3, 0, 1.0)]))
    offsets = np.array([[2.0, 2, 0], [2, -2, 0], [-2, -2, 0], [-2, 2, 0]])
    ref = (
        np.zeros(3),
        np.array([[0.3], [0.3], [0.0]]),
        np.array([[2 * np.pi / 23], [4 * np.pi / 23], [0.0]]),
        np.zeros((3, 1)),
    )
    ref_c = np.array([0.0, 0.0, 0.2])
    return p, v, rot, w, mhat, rhohat, masses, inertia, graph, offsets, ref_c, ref


@pytest.mark.parametrize(("adaptive", "phi_horizontal"), [(True, 1.0), (True, 0.0), (True, 0.3),
                                                      (False, 1.0)])
def test_exact_force_derivatives_match_finite_differences_along_the_closed_loop(adaptive,
                                                                               phi_horizontal):
    # GIVEN the closed loop of Scenario I at a generic (non-equilibrium) state, the estimator
    # reading the horizontal velocity with the weight phi_horizontal (1: the paper's)
    gains = PAPER_GAINS._replace(phi_horizontal=phi_horizontal)
    p, v, rot, w, mhat, rhohat, m, j, adj, off, ref_c, ref = _scenario_state()
    team = TeamState(p, v, rot, w, m, j, np.full(4, -1), np.ones(4), np.zeros(4))
    law = LawInputs(mhat, rhohat, m.copy(), adj, off, ref_c, ref[1], ref[2], ref[3], gains,
                    adaptive)

    def rates(t, x):
        return _oracle_rates(t, OracleState(*x), team, law)

    def rk4(t, x, h):
        def add(x, k, c):
            return tuple(xi + c * ki for xi, ki in zip(x, k[:6], strict=True))

        k1 = rates(t, x)
        k2 = rates(t + h / 2, add(x, k1, h / 2))
        k3 = rates(t + h / 2, add(x, k2, h / 2))
        k4 = rates(t + h, add(x, k3, h))
        out = tuple(
            xi + h / 6 * (a + 2 * b + 2 * c + d)
            for xi, a, b, c, d in zip(x, k1[:6], k2[:6], k3[:6], k4[:6], strict=True)
        )
        orthonormalise(out[2])
        return out

    # WHEN u is sampled along the exact flow at h = 2e-4 (fine RK4 substeps)
    h = 2e-4
    x = (p, v, rot, w, mhat, rhohat)
    samples = []
    t = 0.0
    for _ in range(5):
        samples.append(rates(t, x)[6].copy())
        for _ in range(20):
            x = rk4(t, x, h / 20)
            t += h / 20
    u = np.array(samples)
    du_fd = (u[0] - 8 * u[1] + 8 * u[3] - u[4]) / (12 * h)
    ddu_fd = (-u[0] + 16 * u[1] - 30 * u[2] + 16 * u[3] - u[4]) / (12 * h * h)
    # THEN the closed form of spec 2.9 at the middle sample agrees
    from gcs.control.derivatives import force_derivatives
    from gcs.control.formation import reference_velocity
    from gcs.control.law import TeamMeasurement, position_stage
    from gcs.sim.loop import _acceleration

    x_mid = (p, v, rot, w, mhat, rhohat)
    t_mid = 0.0
    for _ in range(40):
        x_mid = rk4(t_mid, x_mid, h / 20)
        t_mid += h / 20
    pm, vm, rm, wm, mh, rh = x_mid
    refm = reference_velocity(t_mid, ref_c, ref[1], ref[2], ref[3])
    stage = position_stage(pm, vm, rm, mh, m, adj, off, refm, gains, adaptive)
    uu = stage.force_n
    acc = _acceleration(rm, stage.thrust_n, m, gains.gravity_mps2)
    du, ddu = force_derivatives(TeamMeasurement(pm, vm, acc, rm, wm), stage, mh, 1.0 / m, adj,
                                refm, gains, adaptive)
    assert np.allclose(uu, u[2], atol=1e-12)
    assert np.abs(du - du_fd).max() / np.abs(du_fd).max() < 1e-6
    assert np.abs(ddu - ddu_fd).max() / np.abs(ddu_fd).max() < 1e-3
