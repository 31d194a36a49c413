"""Command attitude (14) and its body rates (spec 2.4, 2.5) against identities and finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from gcs.control.geometry import (
    command_angular_velocity,
    command_attitude,
    hat,
    is_nonsingular,
    rotation_from_rpy,
    turn_about_thrust_axis,
    vee,
)

finite = st.floats(-50.0, 50.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.tuples(finite, finite, finite))
def test_hat_vee_round_trip_and_cross_product(v):
    # GIVEN a vector WHEN hatted THEN it acts as the cross product and vee inverts it
    v = np.array(v)
    y = np.array([0.3, -1.2, 2.0])
    assert np.allclose(hat(v) @ y, np.cross(v, y))
    assert np.allclose(vee(hat(v)), v)


@settings(max_examples=300, deadline=None)
@given(st.tuples(finite, finite, st.floats(-50.0, 50.0, allow_nan=False)))
def test_command_attitude_is_a_rotation_taking_e3_to_the_force_direction(u):
    # GIVEN a command force away from the singular ray {(0, 0, u_z <= 0)}
    u = np.array([u])
    norm = np.linalg.norm(u)
    assume(norm > 1e-3 and 1.0 + u[0, 2] / norm > 1e-3)
    # WHEN the command attitude is extracted
    rc = command_attitude(u)[0]
    # THEN it is orthonormal with det 1 and R^c e3 = u/|u|, and u = T R^c e3 with T = |u|
    assert np.allclose(rc.T @ rc, np.eye(3), atol=1e-9)
    assert np.linalg.det(rc) == pytest.approx(1.0, abs=1e-9)
    assert np.allclose(rc[:, 2], u[0] / norm, atol=1e-12)
    assert np.allclose(norm * rc[:, 2], u[0], atol=1e-9)


def test_command_attitude_matches_the_corrected_entries_of_eq_14():
    # GIVEN u with all components nonzero WHEN extracted THEN the (2,2) entry is
    # (u_z + u_x^2/(|u| + u_z))/|u| (the OCR's u_y^2 is wrong) and the (1,1) entry uses u_y^2
    u = np.array([[1.0, 2.0, 5.0]])
    n = np.linalg.norm(u)
    rc = command_attitude(u)[0]
    assert rc[1, 1] == pytest.approx((5.0 + 1.0 / (n + 5.0)) / n)
    assert rc[0, 0] == pytest.approx((5.0 + 4.0 / (n + 5.0)) / n)


def test_singular_force_is_flagged():
    # GIVEN forces on the singular ray, zero, and just off it THEN only the last is admissible
    u = np.array([[0.0, 0.0, -3.0], [0.0, 0.0, 0.0], [1e-3, 0.0, -3.0], [0.0, 0.0, 3.0]])
    assert is_nonsingular(u).tolist() == [False, False, True, True]


def _smooth_force(rng: np.random.Generator):
    """A random smooth u(t) with its analytic first and second derivatives, tilts up to ~175 deg."""
    c = rng.normal(size=(3, 3)) * np.array([[3.0], [3.0], [1.0]])
    w = rng.uniform(0.5, 3.0, size=(3, 3))
    ph = rng.uniform(0, 2 * np.pi, size=(3, 3))
    bias = np.array([rng.normal() * 2, rng.normal() * 2, rng.uniform(-1.0, 8.0)])

    def u(t: float, order: int = 0) -> np.ndarray:
        arg = w * t + ph
        if order == 0:
            return bias + (c * np.sin(arg)).sum(axis=1)
        if order == 1:
            return (c * w * np.cos(arg)).sum(axis=1)
        return -(c * w * w * np.sin(arg)).sum(axis=1)

    return u


def _fd4(f, t: float, h: float):
    return (f(t - 2 * h) - 8 * f(t - h) + 8 * f(t + h) - f(t + 2 * h)) / (12 * h)


@pytest.mark.parametrize("seed", range(20))
def test_command_angular_velocity_matches_finite_differences_of_rc(seed):
    # GIVEN a smooth random u(t)
    rng = np.random.default_rng(seed)
    u = _smooth_force(rng)

    def rc_of(t: float) -> np.ndarray:
        return command_attitude(u(t)[None, :])[0]

    def omega_fd(t: float) -> np.ndarray:
        return vee(rc_of(t).T @ _fd4(rc_of, t, 1e-4))

    def omega_closed(t: float) -> tuple[np.ndarray, np.ndarray]:
        uu = u(t)[None, :]
        wc, dwc = command_angular_velocity(
            uu, u(t, 1)[None, :], u(t, 2)[None, :], command_attitude(uu)
        )
        return wc[0], dwc[0]

    worst_w = worst_dw = 0.0
    for t in np.linspace(0.0, 3.0, 31):
        if not is_nonsingular(u(t)[None, :])[0] or 1 + u(t)[2] / np.linalg.norm(u(t)) < 0.02:
            continue
        wc, dwc = omega_closed(t)
        # WHEN compared with finite differences of R^c(u(t)) alone
        w_ref = omega_fd(t)
        dw_ref = _fd4(omega_fd, t, 1e-3)
        worst_w = max(worst_w, np.linalg.norm(wc - w_ref) / max(1.0, np.linalg.norm(w_ref)))
        worst_dw = max(worst_dw, np.linalg.norm(dwc - dw_ref) / max(1.0, np.linalg.norm(dw_ref)))
    # THEN the closed forms of spec 2.5 agree to the finite-difference floor
    assert worst_w < 1e-7
    assert worst_dw < 1e-4


def test_rotation_from_rpy_is_zyx():
    # GIVEN a pure yaw of 90 deg THEN body x points to world y (north)
    r = rotation_from_rpy(0.0, 0.0, np.pi / 2)
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])
    r = rotation_from_rpy(0.2, -0.4, 1.1)
    assert np.allclose(r.T @ r, np.eye(3))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_turned_command_keeps_the_thrust_axis_and_its_rates_match_finite_differences(seed):
    # GIVEN a smooth random u(t) and a heading turn psi per call
    rng = np.random.default_rng(seed)
    u = _smooth_force(rng)
    psi = np.array([rng.uniform(-np.pi, np.pi)])

    def turned(t: float):
        uu = u(t)[None, :]
        rc = command_attitude(uu)
        wc, dwc = command_angular_velocity(uu, u(t, 1)[None, :], u(t, 2)[None, :], rc)
        return turn_about_thrust_axis(rc, wc, dwc, psi)

    def rc_of(t: float) -> np.ndarray:
        return turned(t)[0][0]

    def omega_fd(t: float) -> np.ndarray:
        return vee(rc_of(t).T @ _fd4(rc_of, t, 1e-4))

    worst_w = worst_dw = 0.0
    for t in np.linspace(0.0, 3.0, 31):
        if not is_nonsingular(u(t)[None, :])[0] or 1 + u(t)[2] / np.linalg.norm(u(t)) < 0.02:
            continue
        rc2, wc2, dwc2 = turned(t)
        rc = command_attitude(u(t)[None, :])[0]
        # THEN the thrust axis is the command force's, the rotation proper, and the heading moved
        np.testing.assert_allclose(rc2[0][:, 2], rc[:, 2], atol=1e-14)
        np.testing.assert_allclose(rc2[0].T @ rc2[0], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(rc.T @ rc2[0], rotation_from_rpy(0.0, 0.0, psi[0]),
                                   atol=1e-12)
        # and its rate and rate derivative are the turned closed forms
        w_ref = omega_fd(t)
        dw_ref = _fd4(omega_fd, t, 1e-3)
        worst_w = max(worst_w, np.linalg.norm(wc2[0] - w_ref) / max(1.0, np.linalg.norm(w_ref)))
        worst_dw = max(worst_dw,
                       np.linalg.norm(dwc2[0] - dw_ref) / max(1.0, np.linalg.norm(dw_ref)))
    assert worst_w < 1e-7
    assert worst_dw < 1e-4


def test_no_turn_is_the_papers_command_unchanged():
    u = np.array([[0.5, -0.3, 9.0], [0.0, 0.0, 5.0]])
    rc = command_attitude(u)
    wc, dwc = np.ones((2, 3)), np.ones((2, 3))
    rc2, wc2, dwc2 = turn_about_thrust_axis(rc, wc, dwc, np.zeros(2))
    assert rc2 is rc and wc2 is wc and dwc2 is dwc
