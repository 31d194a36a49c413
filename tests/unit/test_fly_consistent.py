"""The law's velocity made consistent with the reported position (gcs/fly/consistent.py)."""

import numpy as np
import pytest

from gcs.control.consistency import VELOCITY_MAX_MPS
from gcs.fly.consistent import VelocityConsistency


def feed(f: VelocityConsistency, t: np.ndarray, p: np.ndarray, v: np.ndarray) -> None:
    """Samples of one vehicle (rows of t, p, v) fed one by one."""
    for k in range(len(t)):
        f.update(p[k][None], v[k][None], np.array([t[k]]), np.array([True]))


def test_consistent_position_and_velocity_leave_the_velocity_alone():
    t = np.arange(0.0, 5.0, 0.01)
    a = np.array([0.3, -0.2, 0.1])
    v = np.array([0.5, 0.1, -0.2]) + t[:, None] * a
    p = np.array([1.0, 2.0, 3.0]) + np.array([0.5, 0.1, -0.2]) * t[:, None] + 0.5 * a * t[:, None] ** 2
    f = VelocityConsistency(1, 1.0)
    feed(f, t, p, v)
    assert np.abs(f.correction_mps).max() < 1e-9
    assert f.resets[0] == 0


def test_a_velocity_that_misses_the_positions_rate_is_corrected_at_low_frequency():
    # the position moves 0.2 m/s faster east than the reported velocity says
    t = np.arange(0.0, 10.0, 0.008)
    v = np.tile([0.1, 0.0, 0.0], (len(t), 1))
    p = np.column_stack([0.3 * t, 0.0 * t, 0.0 * t])
    f = VelocityConsistency(1, 1.0)
    feed(f, t[:126], p[:126], v[:126])  # one time constant
    assert f.correction_mps[0, 0] == pytest.approx(0.2 * (1 - np.exp(-1.0)), rel=0.02)
    feed(f, t[126:], p[126:], v[126:])
    assert f.velocity(v[-1:])[0] == pytest.approx([0.3, 0.0, 0.0], abs=1e-3)


def test_a_position_jump_a_gap_and_a_nonfinite_row_move_nothing():
    f = VelocityConsistency(2, 1.0)
    z = np.zeros((2, 3))
    ok = np.array([True, True])
    f.update(z, z, np.array([0.0, 0.0]), ok)
    jumped = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # 1 m in 10 ms: an estimator reset
    f.update(jumped, z, np.array([0.01, 0.01]), ok)
    assert f.resets.tolist() == [1, 0]
    assert not f.correction_mps.any()
    f.update(jumped + 0.5, z, np.array([1.0, 1.0]), ok)  # 0.99 s apart: a gap
    assert not f.correction_mps.any()
    f.update(np.full((2, 3), np.nan), z, np.array([1.01, 1.01]), np.array([False, False]))
    f.update(jumped + 0.5, z, np.array([1.02, 1.02]), ok)  # the NaN row was not taken as a sample
    assert not f.correction_mps.any()


def test_the_correction_is_bounded():
    t = np.arange(0.0, 20.0, 0.01)
    v = np.zeros((len(t), 3))
    p = np.column_stack([2.0 * t, 0.0 * t, 0.0 * t])  # the position runs 2 m/s, velocity says 0
    f = VelocityConsistency(1, 1.0)
    feed(f, t, p, v)
    assert f.correction_mps[0, 0] == VELOCITY_MAX_MPS
    assert f.clamped[0] > 0


def test_a_disagreement_as_large_as_px4_sihs_is_followed_not_clamped():
    # GIVEN the reported velocity 0.9 m/s slower east than the position's rate for 3 s, the
    # largest low-passed disagreement of PX4 v1.16 SIH's estimates in formation flights
    # (gcs/control/consistency.py, VELOCITY_MAX_MPS), at T = 0.2 s and 100 Hz
    t = np.arange(0.0, 3.0, 0.01)
    p = np.column_stack([0.9 * t, 0.0 * t, 0.0 * t])
    f = VelocityConsistency(1, 0.2)
    feed(f, t, p, np.zeros((len(t), 3)))
    # THEN the law's velocity is the position's rate, and no update was clamped
    assert f.velocity(np.zeros((1, 3)))[0] == pytest.approx([0.9, 0.0, 0.0], abs=1e-3)
    assert f.clamped[0] == 0


def test_off_is_the_reported_velocity():
    f = VelocityConsistency(1, 0.0)
    t = np.arange(0.0, 2.0, 0.01)
    p = np.column_stack([0.3 * t, 0.0 * t, 0.0 * t])
    feed(f, t, p, np.zeros((len(t), 3)))
    v = np.array([[0.1, 0.2, 0.3]])
    assert f.velocity(v) is v


def test_an_acceleration_read_through_a_tilted_estimate_is_corrected_to_the_velocitys_rate():
    from gcs.fly.consistent import AccelerationConsistency

    # GIVEN a vehicle accelerating as a sine, its velocity reported exactly, and the accelerometer
    # turned to the world by an attitude estimate 0.03 rad off in roll: g * 0.03 m/s^2 east that
    # the vehicle does not have
    t = np.arange(0.0, 6.0, 0.01)
    a_true = np.column_stack([0.5 * np.sin(t), 0.2 * np.cos(2 * t), 0.0 * t])
    v = np.column_stack([0.5 * (1 - np.cos(t)), 0.1 * np.sin(2 * t), 0.0 * t])
    bias = np.array([0.0, 9.81 * 0.03, 0.0])
    f = AccelerationConsistency(1, 0.5)
    for k in range(len(t)):
        f.update(v[k][None], (a_true[k] + bias)[None], np.array([t[k]]), np.array([True]))
    # THEN after a dozen time constants the law reads the true acceleration, to the trapezoid's
    # error on these 10 ms samples
    assert f.corrected((a_true[-1] + bias)[None])[0] == pytest.approx(a_true[-1], abs=2e-3)
    assert f.resets[0] == 0 and f.clamped[0] == 0
    assert f.report(0)["correction_last_enu_mps2"][1] == pytest.approx(-bias[1], abs=2e-3)


def test_a_velocity_step_is_a_reset_not_an_acceleration():
    from gcs.fly.consistent import AccelerationConsistency

    f = AccelerationConsistency(1, 0.5)
    z = np.zeros((1, 3))
    ok = np.array([True])
    f.update(z, z, np.array([0.0]), ok)
    f.update(np.array([[0.5, 0.0, 0.0]]), z, np.array([0.01]), ok)  # 0.5 m/s in 10 ms: 50 m/s^2
    assert f.resets[0] == 1 and not f.correction.any()
    f.update(np.array([[0.5, 0.0, 0.0]]), np.array([[np.nan, 0.0, 0.0]]), np.array([0.02]), ok)
    assert not f.correction.any()  # a NaN reading is not a sample


@pytest.mark.parametrize("rate_mps", [0.3, 0.9, 2.0, 6.0])
def test_gcs_sims_filter_is_gcs_flys_on_the_same_samples(rate_mps):
    # GIVEN a position running east at rate_mps while the reported velocity says 0: followed
    # (0.3, 0.9 m/s), clamped (2 m/s) or a jump every pair (6 m/s, above VELOCITY_JUMP_MPS)
    from gcs.sim.noise import _complementary

    t = np.arange(0.0, 4.0, 0.01)
    p = np.column_stack([rate_mps * t, 0.0 * t, -0.1 * t])
    fly = VelocityConsistency(1, 0.2)
    c, last, out = np.zeros(3), np.full(6, np.nan), np.empty(3)
    for k in range(len(t)):
        fly.update(p[k][None], np.zeros((1, 3)), np.array([t[k]]), np.array([True]))
        _complementary(0.2, c, last, p[k], np.zeros(3), 0.01, VELOCITY_MAX_MPS, 5.0, out)
        # THEN gcs sim's compiled copy reads the law's velocity as gcs fly does, tick by tick
        assert out == pytest.approx(fly.velocity(np.zeros((1, 3)))[0], abs=1e-12)
    assert out[0] == pytest.approx(min(rate_mps, VELOCITY_MAX_MPS) if rate_mps < 5 else 0.0,
                                   abs=1e-3)
