"""Position loop (21), (23), (24): properties and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gcs.control.formation import (
    adjacency_from_edges,
    edge_list,
    is_connected,
    laplacian,
    pair_offsets,
    reference_velocity,
    unreachable,
)
from gcs.control.gains import PAPER_GAINS
from gcs.control.law import position_stage
from gcs.control.position import force_law, mass_estimator_rate, phi, sliding_variable

RING = adjacency_from_edges(4, [(0, 1, 1.0), (1, 2, 1.0), (2, 3, 1.0), (3, 0, 1.0)])
RING_EDGES = edge_list(RING)
SQUARE = np.array([[2.0, 2, 0], [2, -2, 0], [-2, -2, 0], [-2, 2, 0]])
REF = reference_velocity(
    0.7,
    np.array([0.0, 0, 0.2]),
    np.array([[0.3], [0.3], [0.0]]),
    np.array([[2 * np.pi / 23], [4 * np.pi / 23], [0.0]]),
    np.zeros((3, 1)),
)

vec = arrays(np.float64, (4, 3), elements=st.floats(-1e3, 1e3, allow_nan=False))
vel = arrays(np.float64, (4, 3), elements=st.floats(-50, 50, allow_nan=False))
mhats = arrays(np.float64, (4,), elements=st.floats(0.05, 20.0))


@settings(max_examples=200, deadline=None)
@given(vec, vel, mhats, st.tuples(*(st.floats(-1e3, 1e3, allow_nan=False),) * 3))
def test_force_law_is_translation_invariant_bounded_and_finite(p, v, mhat, shift):
    # GIVEN any team state WHEN every vehicle is shifted by the same vector
    u, *_ = force_law(p, v, mhat, mhat, RING_EDGES, SQUARE, REF, PAPER_GAINS, True)
    u2, *_ = force_law(p + np.array(shift), v, mhat, mhat, RING_EDGES, SQUARE, REF, PAPER_GAINS,
                       True)
    # THEN the command force is unchanged (the law sees only relative positions)
    np.testing.assert_allclose(u, u2, atol=1e-9 * (1 + np.abs(u).max()))
    # AND it is finite and bounded by kappa (2 alpha_p sqrt3 sigma + g + |v_r'|), kappa < alpha_m mhat
    assert np.isfinite(u).all()
    bound = (
        PAPER_GAINS.alpha_m
        * mhat
        * (2 * PAPER_GAINS.alpha_p * np.sqrt(3) + 9.81 + np.abs(REF[1]).sum())
    )
    assert (np.linalg.norm(u, axis=1) <= bound + 1e-9).all()
    # AND with alpha_p < g/(2 sigma) the vertical component stays positive (the basis of u_z > 0)
    assert (u[:, 2] > 0).all()


@settings(max_examples=100, deadline=None)
@given(vel, st.floats(0.0, 1.0))
def test_phi_is_in_1_3(v, horizontal):
    values = phi(v, 1.0, horizontal)
    assert ((values > 1.0 - 1e-12) & (values < 3.0 + 1e-12)).all()
    # AND the horizontal velocity counts with its weight: none at 0, the paper's sum at 1
    vertical = 2.0 + np.tanh(v[:, 2]) / 3.0
    paper = 2.0 + np.tanh(v).sum(axis=1) / 3.0
    np.testing.assert_allclose(values, vertical + horizontal * (paper - vertical), atol=1e-12)


def test_sliding_variable_is_the_laplacian_form():
    # GIVEN random positions WHEN s is formed THEN s = c_p (L (x) I)(p - theta) + v - v_r
    rng = np.random.default_rng(3)
    p, v = rng.normal(size=(2, 4, 3))
    s, ve = sliding_variable(p, v, RING_EDGES, SQUARE, 4.0, REF)
    expected = 4.0 * laplacian(RING) @ (p - SQUARE) + v - REF[0]
    np.testing.assert_allclose(s, expected, atol=1e-12)
    np.testing.assert_allclose(ve, v - REF[0])
    # AND a team exactly in formation, moving at v_r, has s = 0
    s0, _ = sliding_variable(SQUARE + 5.0, np.tile(REF[0], (4, 1)), RING_EDGES, SQUARE, 4.0, REF)
    np.testing.assert_allclose(s0, 0.0, atol=1e-12)


@pytest.mark.parametrize("horizontal", [1.0, 0.0, 0.3])
def test_mass_estimator_invariance_identity_37(horizontal):
    # GIVEN a random state and the model v' = -g e3 + T R e3 / m (spec 2.3), phi weighting the
    # horizontal velocity by `horizontal` (1: the paper's)
    gains = PAPER_GAINS._replace(phi_horizontal=horizontal)
    weight = np.array([horizontal, horizontal, 1.0])
    rng = np.random.default_rng(11)
    m = np.array([0.85, 1.2, 0.35, 3.4])
    p, v = rng.normal(size=(2, 4, 3))
    rot = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(4)])
    rot *= np.sign(np.linalg.det(rot))[:, None, None]
    mhat = rng.uniform(0.5, 4.0, size=4)
    u, a, s, ve, ph, kappa, t_n, mhat_rate = position_stage(
        p, v, rot, mhat, m, RING_EDGES, SQUARE, REF, gains, True
    )
    np.testing.assert_allclose(ph, 2.0 + (weight * np.tanh(v)).sum(axis=1) / 3.0)
    vdot = -9.81 * np.array([0, 0, 1.0]) + t_n[:, None] * rot[:, :, 2] / m[:, None]
    phidot = (weight * (1 - np.tanh(v) ** 2) * vdot).sum(axis=1) / 3.0
    # WHEN mt = alpha_m mhat - phi m is differentiated
    mt = mhat - ph * m
    mt_dot = mhat_rate - phidot * m
    # THEN it obeys (37) with the corrected sign of (24)
    expected = -9.81 * (1 - np.tanh(v[:, 2]) ** 2) / (3.0 * ph) * mt
    np.testing.assert_allclose(mt_dot, expected, atol=1e-12)
    direct = mass_estimator_rate(v, rot, t_n, mhat, ph, gains)
    np.testing.assert_allclose(direct, mhat_rate)


@pytest.mark.parametrize("horizontal", [1.0, 0.0])
def test_the_vertical_estimator_is_blind_to_tilt_and_horizontal_velocity(horizontal):
    # GIVEN one 1 kg vehicle hovering level and still, its estimate at the truth
    gains = PAPER_GAINS._replace(phi_horizontal=horizontal)
    still, level, thrust = np.zeros((1, 3)), np.eye(3)[None], np.array([9.81])
    phi_true = phi(still, 1.0, horizontal)
    mhat = phi_true.copy()  # alpha_m mhat / phi = 1 kg
    assert abs(mass_estimator_rate(still, level, thrust, mhat, phi_true, gains)[0]) < 1e-12
    # WHEN the estimator reads its attitude 1 deg tilted, or its velocity 0.1 m/s off east and
    # north (the size of PX4's estimate errors, docs/gcs.md "What the mass estimate reads")
    tilt = np.deg2rad(1.0)
    tilted = np.array([[[1.0, 0.0, 0.0],
                        [0.0, np.cos(tilt), -np.sin(tilt)],
                        [0.0, np.sin(tilt), np.cos(tilt)]]])
    moving = np.array([[0.1, 0.1, 0.0]])
    drift = mass_estimator_rate(still, tilted, thrust, mhat, phi_true, gains)[0] / (9.81 / 3.0)
    jump = mhat[0] / phi(moving, 1.0, horizontal)[0] - 1.0  # alpha_m mhat / phi, at once
    # THEN the paper's estimate drifts at sin(tilt) of the scale g / 3 and jumps by the
    # velocity's share of phi; the vertical one drifts at 1 - cos(tilt) and does not jump
    if horizontal == 1.0:
        assert drift == pytest.approx(np.cos(tilt) - np.sin(tilt) - 1.0, rel=1e-9)
        assert jump == pytest.approx(2.0 / (2.0 + 2.0 * np.tanh(0.1) / 3.0) - 1.0, rel=1e-9)
        assert abs(drift) > 0.017 and abs(jump) > 0.03
    else:
        assert drift == pytest.approx(np.cos(tilt) - 1.0, rel=1e-9)
        assert abs(drift) < 2e-4 and jump == 0.0


def test_baseline_uses_the_nominal_mass_and_does_not_adapt():
    rng = np.random.default_rng(5)
    p, v = rng.normal(size=(2, 4, 3))
    rot = np.tile(np.eye(3), (4, 1, 1))
    nominal = np.array([0.85, 1.2, 0.35, 3.4])
    u, a, s, ve, ph, kappa, t_n, mhat_rate = position_stage(
        p, v, rot, np.ones(4), nominal, RING_EDGES, SQUARE, REF, PAPER_GAINS, False
    )
    np.testing.assert_allclose(kappa, nominal)
    np.testing.assert_allclose(u, nominal[:, None] * a)
    assert not mhat_rate.any()


def test_graph_helpers():
    # GIVEN the ring and a graph with an isolated vertex
    assert is_connected(RING)
    split = adjacency_from_edges(4, [(0, 1, 1.0), (1, 2, 2.0)])
    assert not is_connected(split) and unreachable(split) == [3]
    # THEN the Laplacian has zero row sums and one zero eigenvalue for a connected graph
    eig = np.linalg.eigvalsh(laplacian(RING))
    assert abs(eig[0]) < 1e-12 and eig[1] > 0.5
    theta = pair_offsets(SQUARE)
    np.testing.assert_allclose(theta[0, 2], [4.0, 4.0, 0.0])
    with pytest.raises(ValueError, match="self loop"):
        adjacency_from_edges(3, [(1, 1, 1.0)])
    with pytest.raises(ValueError, match="weight must be > 0"):
        adjacency_from_edges(3, [(0, 1, 0.0)])


def test_reference_velocity_derivatives_match_finite_differences():
    args = (
        np.array([0.1, 0, 0.2]),
        np.array([[0.3, 0.1], [0.3, 0.0], [0.0, 0.05]]),
        np.array([[0.27, 1.3], [0.55, 0.0], [0.0, 2.0]]),
        np.array([[0.0, 0.4], [0.0, 0.0], [0.0, 1.0]]),
    )
    h = 1e-4
    for order in range(3):
        fd = (
            reference_velocity(1.3 + h, *args)[order] - reference_velocity(1.3 - h, *args)[order]
        ) / (2 * h)
        np.testing.assert_allclose(fd, reference_velocity(1.3, *args)[order + 1], atol=1e-6)
