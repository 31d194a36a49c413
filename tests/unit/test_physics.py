"""Unit tests of the nominal quadrotor model and mixer against closed forms and invariants."""

from __future__ import annotations

import ast
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from flightkit import physics as ph
from flightkit.physics import GRAVITY_MPS2 as G

Arr = np.ndarray
JIT_DISABLED = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")


@njit(cache=True)
def _integrate(
    p: Arr,
    v: Arr,
    r: Arr,
    w: Arr,
    thrust: Arr,
    torque: Arr,
    mass: Arr,
    inertia: Arr,
    dt_s: float,
    steps: int,
) -> None:
    """rk4_step repeated inside njit code, as a simulation loop would call it."""
    for _ in range(steps):
        ph.rk4_step(p, v, r, w, thrust, torque, mass, inertia, dt_s)


def _rot(axis: int, angle_rad: float) -> np.ndarray:
    """Elementary rotation about world axis 0/1/2 (body-to-world)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def _ortho_error(r: np.ndarray) -> float:
    return float(np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max())


def _tumbling_team() -> tuple[np.ndarray, ...]:
    """Table I bodies, torque-free and thrust-free, tumbling at up to 30 rad/s."""
    mass, inertia = ph.table_i_arrays()
    w = np.array([[20.0, -15.0, 10.0], [3.0, 25.0, -4.0], [-30.0, 2.0, 6.0], [5.0, 5.0, 18.0]])
    r = np.ascontiguousarray(_random_rotations(np.random.default_rng(3), 4))
    return np.zeros((4, 3)), np.zeros((4, 3)), r, w, np.zeros(4), np.zeros((4, 3)), mass, inertia


def test_table_i_matches_the_paper() -> None:
    # GIVEN the paper's Table I  WHEN read as arrays  THEN masses and diagonal inertias match
    mass, inertia = ph.table_i_arrays()
    assert [a.name for a in ph.TABLE_I] == ["UAV1", "UAV2", "UAV3", "UAV4"]
    np.testing.assert_array_equal(mass, [0.85, 1.2, 0.35, 3.4])
    np.testing.assert_allclose(
        inertia,
        [
            [4.856e-2, 4.856e-2, 8.801e-2],
            [0.1522, 0.1522, 0.3],
            [0.0256, 0.0256, 0.052],
            [0.354, 0.354, 0.654],
        ],
        rtol=1e-15,
    )


def test_hover_equilibrium_holds_for_10_s() -> None:
    # GIVEN each Table I vehicle level (various yaws) with T = m g and zero torque
    mass, inertia = ph.table_i_arrays()
    p0 = np.array([[4.0, 4.0, 9.0], [3.0, -4.0, 11.0], [-5.0, -4.0, 12.0], [-1.0, 3.0, 8.0]])
    r0 = np.stack([_rot(2, yaw) for yaw in (0.0, 0.7, -2.0, 3.0)])
    p, v, r, w = p0.copy(), np.zeros((4, 3)), r0.copy(), np.zeros((4, 3))
    # WHEN integrated for 10 s at 1 ms
    _integrate(p, v, r, w, mass * G, np.zeros((4, 3)), mass, inertia, 1e-3, 10_000)
    # THEN nothing moves
    np.testing.assert_allclose(p, p0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v, 0.0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(r, r0, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(w, 0.0)


def test_free_fall_follows_the_parabola_while_tumbling() -> None:
    # GIVEN zero thrust, an initial velocity and a tumbling attitude
    p0, _, r, w, thrust, torque, mass, inertia = _tumbling_team()
    p0 = p0 + np.array([1.0, -2.0, 50.0])
    v0 = np.tile([0.5, -1.0, 3.0], (4, 1))
    p, v = p0.copy(), v0.copy()
    # WHEN integrated for 2 s
    _integrate(p, v, r, w, thrust, torque, mass, inertia, 1e-3, 2000)
    # THEN p = p0 + v0 t - g t^2/2 e3 (RK4 is exact on this quadratic)
    t = 2.0
    expected = p0 + v0 * t - 0.5 * G * t * t * np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(p, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, v0 - G * t * np.array([0.0, 0.0, 1.0]), rtol=0, atol=1e-9)


def test_torque_from_rest_gives_inverse_inertia_acceleration() -> None:
    # GIVEN a level body at rest under torque tau
    mass, inertia = ph.table_i_arrays()
    torque = np.array(
        [[0.02, -0.01, 0.005], [0.0, 0.1, 0.0], [-0.01, 0.01, 0.02], [0.3, 0.2, -0.1]]
    )
    state = (np.zeros((4, 3)), np.zeros((4, 3)), np.tile(np.eye(3), (4, 1, 1)), np.zeros((4, 3)))
    args = (*state, mass * G, torque, mass, inertia)
    alpha = torque / inertia
    # WHEN the derivatives are evaluated  THEN omega' = J^-1 tau and nothing else changes
    p_dot, v_dot, r_dot, w_dot = ph.derivatives(*args)
    np.testing.assert_allclose(w_dot, alpha, rtol=1e-15)
    np.testing.assert_allclose(v_dot, 0.0, atol=1e-14)
    assert np.all(p_dot == 0.0) and np.all(r_dot == 0.0)
    # WHEN one 1 ms step is taken  THEN omega = alpha dt and R = I + hat(alpha) dt^2/2 (+O(dt^3))
    dt = 1e-3
    _, _, r1, w1 = ph.rk4_step_copy(*args, dt)
    np.testing.assert_allclose(w1, alpha * dt, rtol=1e-6, atol=0)
    expected_r = np.stack([np.eye(3) + ph.hat(a) * dt * dt / 2 for a in alpha])
    np.testing.assert_allclose(r1, expected_r, rtol=0, atol=1e-9)


def test_derivatives_agree_with_the_model_written_in_numpy() -> None:
    # GIVEN random states and inputs
    rng = np.random.default_rng(7)
    n = 6
    p, v, w, tau = (rng.normal(size=(n, 3)) for _ in range(4))
    r = _random_rotations(rng, n)
    thrust, mass = rng.uniform(0, 30, n), rng.uniform(0.3, 4, n)
    inertia = rng.uniform(0.02, 0.7, (n, 3))
    # WHEN evaluated by derivatives()
    p_dot, v_dot, r_dot, w_dot = ph.derivatives(p, v, r, w, thrust, tau, mass, inertia)
    # THEN they equal eqs (6)-(9) written with matrices
    e3 = np.array([0.0, 0.0, 1.0])
    np.testing.assert_array_equal(p_dot, v)
    np.testing.assert_allclose(v_dot, -G * e3 + (thrust / mass)[:, None] * r[:, :, 2], atol=1e-13)
    np.testing.assert_allclose(r_dot, np.stack([r[i] @ ph.hat(w[i]) for i in range(n)]), atol=1e-14)
    jw = inertia * w
    np.testing.assert_allclose(w_dot, (-np.cross(w, jw) + tau) / inertia, rtol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_spin_about_a_principal_axis_is_steady(axis: int) -> None:
    # GIVEN a torque-free Table I body spinning at 3 rad/s about principal axis `axis`
    mass, inertia = ph.table_i_arrays()
    w0 = np.zeros((4, 3))
    w0[:, axis] = 3.0
    p, v, r, w = np.zeros((4, 3)), np.zeros((4, 3)), np.tile(np.eye(3), (4, 1, 1)), w0.copy()
    # WHEN integrated for 5 s
    _integrate(p, v, r, w, np.zeros(4), np.zeros((4, 3)), mass, inertia, 1e-3, 5000)
    # THEN omega is unchanged and R = rotation about that axis by 15 rad
    np.testing.assert_allclose(w, w0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r, np.tile(_rot(axis, 15.0), (4, 1, 1)), rtol=0, atol=1e-9)


def test_axisymmetric_body_precesses_at_the_closed_form_rate() -> None:
    # GIVEN torque-free axisymmetric bodies (Jx = Jy) with omega(0) = (a, 0, wz)
    mass, inertia = ph.table_i_arrays()
    a, wz = 0.8, 4.0
    w = np.tile([a, 0.0, wz], (4, 1))
    p, v, r = np.zeros((4, 3)), np.zeros((4, 3)), np.tile(np.eye(3), (4, 1, 1))
    # WHEN integrated for 5 s
    _integrate(p, v, r, w, np.zeros(4), np.zeros((4, 3)), mass, inertia, 1e-3, 5000)
    # THEN (wx, wy) has turned by Omega t with Omega = (Jz - Jx)/Jx wz, and wz is constant
    phase = (inertia[:, 2] - inertia[:, 0]) / inertia[:, 0] * wz * 5.0
    expected = np.stack([a * np.cos(phase), a * np.sin(phase), np.full(4, wz)], axis=1)
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-9)


def test_rotation_stays_orthonormal_over_60_s_of_tumbling() -> None:
    # GIVEN bodies tumbling at up to 30 rad/s (RK4 alone drifts off SO(3) by ~1e-6 here)
    p, v, r, w, thrust, torque, mass, inertia = _tumbling_team()
    # WHEN integrated for 60 s at 1 ms
    _integrate(p, v, r, w, thrust, torque, mass, inertia, 1e-3, 60_000)
    # THEN R^T R = I and det R = 1
    assert _ortho_error(r) < 1e-9
    np.testing.assert_allclose(np.linalg.det(r), 1.0, rtol=0, atol=1e-9)


def test_orthonormalise_returns_the_svd_polar_factor() -> None:
    # GIVEN rotations perturbed off SO(3) by 1e-5
    rng = np.random.default_rng(9)
    r = _random_rotations(rng, 20) + 1e-5 * rng.normal(size=(20, 3, 3))
    u, _, vt = np.linalg.svd(r)
    # WHEN orthonormalised in place
    ph.orthonormalise(r)
    # THEN each is the nearest rotation (polar factor U V^T) to rounding
    np.testing.assert_allclose(r, u @ vt, rtol=0, atol=1e-13)
    assert _ortho_error(r) < 1e-15


def test_torque_free_motion_conserves_momentum_and_energy() -> None:
    # GIVEN torque-free tumbling bodies
    p, v, r, w, thrust, torque, mass, inertia = _tumbling_team()
    h0 = np.einsum("nij,nj->ni", r, inertia * w)
    e0 = 0.5 * np.sum(inertia * w * w, axis=1)
    # WHEN integrated for 60 s at 1 ms
    _integrate(p, v, r, w, thrust, torque, mass, inertia, 1e-3, 60_000)
    # THEN world angular momentum R J omega and kinetic energy are conserved
    h1 = np.einsum("nij,nj->ni", r, inertia * w)
    e1 = 0.5 * np.sum(inertia * w * w, axis=1)
    assert np.all(np.linalg.norm(h1 - h0, axis=1) < 1e-8 * np.linalg.norm(h0, axis=1))
    assert np.all(np.abs(e1 - e0) < 1e-8 * e0)


def test_rk4_converges_at_fourth_order() -> None:
    # GIVEN a thrusting, torqued, tumbling team and a fine-step reference over 2 s
    mass, inertia = ph.table_i_arrays()
    w0 = np.array([[2.0, -1.5, 1.0], [0.3, 2.5, -0.4], [-3.0, 0.2, 0.6], [0.5, 0.5, 1.8]])
    torque = np.tile([0.01, -0.02, 0.005], (4, 1))

    def final_state(dt_s: float) -> np.ndarray:
        p, v, r, w = (
            np.zeros((4, 3)),
            np.tile([1.0, 0, 0], (4, 1)),
            np.tile(np.eye(3), (4, 1, 1)),
            w0.copy(),
        )
        _integrate(p, v, r, w, mass * 12.0, torque, mass, inertia, dt_s, round(2.0 / dt_s))
        return np.concatenate([p.ravel(), v.ravel(), r.ravel(), w.ravel()])

    reference = final_state(0.02 / 64)
    # WHEN the step is halved twice
    errors = [np.abs(final_state(dt) - reference).max() for dt in (0.04, 0.02, 0.01)]
    # THEN each halving divides the error by ~16
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(14.0 < q < 18.0 for q in ratios), (errors, ratios)


def test_specific_force_is_thrust_over_mass_along_body_z() -> None:
    # GIVEN random attitudes and thrusts
    rng = np.random.default_rng(11)
    n = 5
    thrust, mass = rng.uniform(0, 40, n), rng.uniform(0.3, 4, n)
    r = _random_rotations(rng, n)
    # WHEN the accelerometer model is evaluated
    f_body = ph.specific_force_body(thrust, mass)
    # THEN it is (0, 0, T/m) and equals R^T (v' + g e3) from the model
    np.testing.assert_allclose(f_body, np.stack([0 * thrust, 0 * thrust, thrust / mass], 1))
    z = np.zeros((n, 3))
    _, v_dot, _, _ = ph.derivatives(z, z, r, z, thrust, z, mass, np.ones((n, 3)))
    np.testing.assert_allclose(np.einsum("nji,nj->ni", r, v_dot + [0, 0, G]), f_body, atol=1e-12)


def test_rk4_step_copy_is_pure_and_equals_in_place_step() -> None:
    # GIVEN a tumbling team  WHEN stepped by both APIs
    state = _tumbling_team()
    before = [a.copy() for a in state]
    copied = ph.rk4_step_copy(*state, 1e-3)
    ph.rk4_step(*state, 1e-3)
    # THEN the copy variant left its inputs alone and both give the same result
    for new, old in zip(copied, before[:4], strict=True):
        assert not np.array_equal(new, old)
    for new, in_place in zip(copied, state[:4], strict=True):
        np.testing.assert_array_equal(new, in_place)


def test_inconsistent_shapes_are_rejected() -> None:
    # GIVEN a rotation array for 3 vehicles in a team of 4  WHEN stepped  THEN ValueError
    p, v, r, w, thrust, torque, mass, inertia = _tumbling_team()
    with pytest.raises(ValueError, match=r"expected shapes \(n,3\),\(n,3\),\(n,3,3\)"):
        ph.rk4_step(p, v, r[:3].copy(), w, thrust, torque, mass, inertia, 1e-3)


@pytest.mark.skipif(JIT_DISABLED, reason="NRT allocation statistics exist only under JIT")
def test_rk4_step_does_not_allocate_per_step() -> None:
    # GIVEN NRT allocation statistics and a warmed-up step loop
    from numba.core.runtime import _nrt_python, rtsys

    state = _tumbling_team()
    _integrate(*state, 1e-3, 1)

    def allocations(steps: int) -> int:
        before = rtsys.get_allocation_stats().alloc
        _integrate(*state, 1e-3, steps)
        return rtsys.get_allocation_stats().alloc - before

    _nrt_python.memsys_enable_stats()
    try:
        # WHEN 1 and 1000 steps are taken  THEN both allocate the same (argument unboxing only)
        assert allocations(1000) == allocations(1)
    finally:
        _nrt_python.memsys_disable_stats()


def test_hat_and_vee_are_inverse_and_hat_is_the_cross_product() -> None:
    # GIVEN random vectors  WHEN hat/vee are applied  THEN hat(a) b = a x b and vee(hat(a)) = a
    rng = np.random.default_rng(5)
    for a, b in rng.normal(size=(10, 2, 3)):
        np.testing.assert_allclose(ph.hat(a) @ b, np.cross(a, b), atol=1e-15)
        np.testing.assert_array_equal(ph.vee(ph.hat(a)), a)


def test_module_is_pure() -> None:
    # GIVEN the module source  WHEN its imports are listed  THEN only numpy/numba/stdlib basics
    tree = ast.parse(Path(ph.__file__).read_text())
    modules = {
        a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
    }
    modules |= {
        n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module
    }
    assert modules <= {"__future__", "dataclasses", "numpy", "numba"}, modules


# --- mixer (51) -------------------------------------------------------------------------------


def _mixer_matrix(d: float, c: float) -> np.ndarray:
    return np.array([[1, 1, 1, 1], [0, -d, 0, d], [d, 0, -d, 0], [c, -c, c, -c]], dtype=float)


def _airframes(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return rng.uniform(0.1, 0.4, n), rng.uniform(0.005, 0.03, n), rng.uniform(2.0, 20.0, n)


def test_wrench_from_rotors_is_eq_51() -> None:
    # GIVEN random rotor thrusts  WHEN mixed  THEN [T, tau] = M f with the paper's M
    rng = np.random.default_rng(1)
    d, c, f_max = _airframes(rng, 8)
    f = rng.uniform(0, 1, (8, 4)) * f_max[:, None]
    thrust, torque = ph.wrench_from_rotors(f, d, c)
    expected = np.stack([_mixer_matrix(d[i], c[i]) @ f[i] for i in range(8)])
    np.testing.assert_allclose(np.column_stack([thrust, torque]), expected, rtol=1e-14, atol=1e-14)


def test_rotors_from_wrench_inverts_feasible_wrenches_exactly() -> None:
    # GIVEN wrenches produced by rotor thrusts within [0, f_max]
    rng = np.random.default_rng(2)
    n = 500
    d, c, f_max = _airframes(rng, n)
    f = rng.uniform(0, 1, (n, 4)) * f_max[:, None]
    thrust, torque = ph.wrench_from_rotors(f, d, c)
    out, limited = np.empty((n, 4)), np.full((n, 3), 7.0)
    # WHEN allocated back  THEN the rotor thrusts are recovered and nothing is reported modified
    assert ph.rotors_from_wrench_into(thrust, torque, d, c, f_max, out, np.ones(len(thrust)),
                                      limited) == 0
    np.testing.assert_allclose(out, f, rtol=0, atol=1e-12)
    assert not limited.any()  # and no axis saturated
    np.testing.assert_array_equal(ph.rotors_from_wrench(thrust, torque, d, c, f_max), out)


def test_rotor_limits_hold_and_priorities_are_kept_for_infeasible_wrenches() -> None:
    # GIVEN random wrenches, most of them beyond the rotor limits
    rng = np.random.default_rng(3)
    n = 2000
    d, c, f_max = _airframes(rng, n)
    thrust = rng.uniform(-1, 6, n) * f_max
    torque = rng.normal(size=(n, 3)) * np.column_stack([d, d, c]) * f_max[:, None]
    out, limited = np.empty((n, 4)), np.empty((n, 3))
    # WHEN allocated
    modified = ph.rotors_from_wrench_into(thrust, torque, d, c, f_max, out, np.ones(len(thrust)),
                                          limited)
    t_out, tau_out = ph.wrench_from_rotors(out, d, c)
    # THEN each axis's saturation flag is the sign of what it asked beyond what the rotors make
    gap = torque - tau_out
    short = np.abs(gap) > 1e-7 * (np.abs(torque) + 1e-6)
    np.testing.assert_array_equal(limited[short], np.sign(gap[short]))
    assert np.all(limited[np.abs(gap) < 1e-12] == 0.0)
    # THEN every rotor is in [0, f_max]
    assert np.all(out >= 0.0) and np.all(out <= f_max[:, None])
    exact = np.all(
        np.isclose(
            np.column_stack([t_out, tau_out]),
            np.column_stack([thrust, torque]),
            rtol=1e-9,
            atol=1e-9,
        ),
        axis=1,
    )
    assert modified == np.count_nonzero(~exact) > n // 2
    # AND roll/pitch torque is kept whenever it alone fits, and its direction always
    rp_fits = np.maximum(np.abs(torque[:, 0]), np.abs(torque[:, 1])) / d <= f_max
    np.testing.assert_allclose(tau_out[rp_fits, :2], torque[rp_fits, :2], rtol=1e-9, atol=1e-9)
    cross = tau_out[:, 0] * torque[:, 1] - tau_out[:, 1] * torque[:, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    assert np.all(tau_out[:, :2] * torque[:, :2] >= -1e-12)
    # AND yaw only shrinks toward zero, never flips
    assert np.all(tau_out[:, 2] * torque[:, 2] >= -1e-12)
    assert np.all(np.abs(tau_out[:, 2]) <= np.abs(torque[:, 2]) + 1e-12)


def test_yaw_gives_way_before_thrust_and_roll() -> None:
    # GIVEN a hover wrench with a roll torque and a yaw demand far beyond the limits
    d, c, f_max = np.array([0.2]), np.array([0.016]), np.array([6.0])
    thrust, torque = np.array([0.85 * G]), np.array([[0.1, 0.0, 5.0]])
    # WHEN allocated
    t_out, tau_out = ph.wrench_from_rotors(ph.rotors_from_wrench(thrust, torque, d, c, f_max), d, c)
    # THEN thrust and roll are exact and yaw is trimmed to the largest feasible value
    np.testing.assert_allclose([t_out[0], *tau_out[0, :2]], [thrust[0], 0.1, 0.0], atol=1e-12)
    # (yaw headroom y = T/4 - |tau_x|/(2d): rotor 2 reaches 0 N first; tau_z = 4 C y)
    headroom_n = thrust[0] / 4 - 0.1 / (2 * 0.2)
    np.testing.assert_allclose(tau_out[0, 2], 4 * 0.016 * headroom_n, atol=1e-12)


def test_max_collective_thrust_is_four_rotors() -> None:
    # GIVEN per-vehicle rotor limits  WHEN asked  THEN 4 f_max
    np.testing.assert_array_equal(ph.max_collective_thrust_n(np.array([6.0, 8.0])), [24.0, 32.0])


_pos = st.floats(0.0, 1.0)


@settings(max_examples=200, deadline=None)
@given(
    fractions=st.lists(_pos, min_size=4, max_size=4),
    d=st.floats(0.05, 0.5),
    c=st.floats(0.005, 0.05),
    f_max=st.floats(0.5, 40.0),
)
def test_property_mixer_round_trip(
    fractions: list[float], d: float, c: float, f_max: float
) -> None:
    # GIVEN any rotor thrusts within limits  WHEN mixed and allocated  THEN they come back
    f = np.array([fractions]) * f_max
    args = (np.array([d]), np.array([c]))
    thrust, torque = ph.wrench_from_rotors(f, *args)
    np.testing.assert_allclose(
        ph.rotors_from_wrench(thrust, torque, *args, np.array([f_max])),
        f,
        rtol=0,
        atol=1e-12 * f_max,
    )


_big = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(thrust=_big, tx=_big, ty=_big, tz=_big, f_max=st.floats(0.5, 40.0))
def test_property_allocation_is_bounded_and_finite(
    thrust: float, tx: float, ty: float, tz: float, f_max: float
) -> None:
    # GIVEN any finite wrench  WHEN allocated  THEN rotor thrusts are finite and within limits
    f = ph.rotors_from_wrench(
        np.array([thrust]),
        np.array([[tx, ty, tz]]),
        np.array([0.2]),
        np.array([0.016]),
        np.array([f_max]),
    )
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0) and np.all(f <= f_max)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rate_radps=st.floats(0.0, 50.0))
def test_property_one_step_stays_finite_and_on_so3(seed: int, rate_radps: float) -> None:
    # GIVEN a random attitude, rates up to 50 rad/s and inputs within Table I-like limits
    rng = np.random.default_rng(seed)
    mass, inertia = ph.table_i_arrays()
    r = np.ascontiguousarray(_random_rotations(rng, 4))
    w = rng.normal(size=(4, 3))
    w *= rate_radps / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
    state = (rng.normal(size=(4, 3)), rng.normal(size=(4, 3)), r, w)
    # WHEN stepped 1 ms
    ph.rk4_step(*state, rng.uniform(0, 80, 4), rng.normal(size=(4, 3)), mass, inertia, 1e-3)
    # THEN the state is finite and R is a rotation
    assert all(np.all(np.isfinite(a)) for a in state)
    assert _ortho_error(r) < 1e-12 and np.allclose(np.linalg.det(r), 1.0, atol=1e-12)


def test_airmode_off_keeps_low_thrust_and_shrinks_the_torque():
    # GIVEN a low collective thrust with a roll/pitch torque that does not fit under it
    thrust = np.array([2.0, 2.0])
    torque = np.array([[0.0, 0.6, 0.05], [0.0, 0.6, 0.05]])
    arm, anti, fmax = np.full(2, 0.25), np.full(2, 0.016), np.full(2, 6.0)
    out, limited = np.empty((2, 4)), np.empty((2, 3))
    # WHEN mixed with MC_AIRMODE 0 (vehicle 0) and 1 (vehicle 1)
    modified = ph.rotors_from_wrench_into(thrust, torque, arm, anti, fmax, out,
                                          np.array([0.0, 1.0]), limited)
    t_out, tau_out = ph.wrench_from_rotors(out, arm, anti)
    # THEN both report the wrench as modified and keep every rotor within limits
    assert modified == 2 and (out >= 0.0).all() and (out <= 6.0).all()
    # AND airmode 0 keeps the commanded thrust, shrinking the pitch torque in the same direction
    assert t_out[0] == pytest.approx(2.0)
    assert 0.0 < tau_out[0, 1] < 0.6
    assert limited[0, 1] == 1.0  # pitch short of its demand: saturated positive
    # AND airmode 1 raises the thrust to deliver the full pitch torque
    assert t_out[1] > 2.0 and tau_out[1, 1] == pytest.approx(0.6)
