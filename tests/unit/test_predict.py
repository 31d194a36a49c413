"""Delay compensation (gcs/control/predict.py): the kinematic predictor and its in-flight audit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gcs.control.law import TeamMeasurement
from gcs.control.predict import (
    MAX_HORIZON_S,
    PredictionAudit,
    horizons_s,
    predict,
    rotation_angle_rad,
    rotation_step,
    uplink_delay_s,
)


def team(n: int = 3, seed: int = 1) -> TeamMeasurement:
    rng = np.random.default_rng(seed)
    return TeamMeasurement(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                           rng.normal(size=(n, 3)),
                           Rotation.random(n, random_state=seed).as_matrix(),
                           rng.normal(size=(n, 3)))


def test_constant_acceleration_and_constant_body_rates_are_predicted_exactly():
    m = team()
    h = np.array([0.0, 0.05, 0.3])
    out = predict(m, h, h)
    for i in range(3):
        # a point under constant acceleration, from the textbook
        p = m.position_m[i] + m.velocity_mps[i] * h[i] + 0.5 * m.acceleration_mps2[i] * h[i] ** 2
        assert np.allclose(out.position_m[i], p)
        assert np.allclose(out.velocity_mps[i], m.velocity_mps[i] + m.acceleration_mps2[i] * h[i])
        # constant body rates: R exp(omega h), composed by scipy from the rotation vector
        r = (Rotation.from_matrix(m.rotation[i])
             * Rotation.from_rotvec(m.omega_radps[i] * h[i])).as_matrix()
        assert np.allclose(out.rotation[i], r, atol=1e-12)
    assert np.array_equal(out.omega_radps, m.omega_radps)
    assert np.array_equal(out.acceleration_mps2, m.acceleration_mps2)


def test_rotation_step_is_a_rotation_near_zero_and_inverts_with_a_negative_horizon():
    r = Rotation.random(4, random_state=3).as_matrix()
    w = np.array([[0.0, 0.0, 0.0], [1e-12, 0.0, 0.0], [3.0, -2.0, 1.0], [0.0, 0.0, 40.0]])
    h = np.full(4, 0.1)
    out = rotation_step(r, w, h)
    assert np.allclose(out @ np.transpose(out, (0, 2, 1)), np.eye(3), atol=1e-12)
    assert np.allclose(out[0], r[0]) and np.allclose(out[1], r[1])
    assert np.allclose(rotation_step(out, w, -h), r, atol=1e-12)
    # the angle turned is |omega| h (wrapped to [0, pi])
    turned = rotation_angle_rad(r, out)
    assert turned[2] == pytest.approx(math.sqrt(14.0) * 0.1)
    assert turned[3] == pytest.approx(2.0 * math.pi - 4.0)  # 4 rad about z: 2 pi - 4 the short way


def test_horizons_are_clamped_and_zero_where_nothing_was_taken_yet():
    taken = np.array([9.95, 10.2, 9.0, -np.inf, np.nan])
    h = horizons_s(10.0, taken)
    assert h.tolist() == pytest.approx([0.05, 0.0, MAX_HORIZON_S, 0.0, 0.0])


def test_the_uplink_delay_is_the_median_of_the_finite_link_delays():
    assert uplink_delay_s(np.array([0.05, 0.06, 0.2, np.nan])) == pytest.approx(0.06)
    assert uplink_delay_s(np.array([np.nan])) == 0.0
    assert uplink_delay_s(np.array([])) == 0.0


def test_the_audit_measures_prediction_and_hold_against_the_samples_reported_later():
    # GIVEN one vehicle moving at 2 m/s east and turning at 1 rad/s in yaw, its samples taken
    # every 10 ms and arriving 50 ms later; each tick predicts to now + 50 ms (the uplink)
    v, w, delay, dt = np.array([2.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), 0.05, 0.01

    def state(t: float) -> tuple[np.ndarray, np.ndarray]:
        return v * t, Rotation.from_rotvec(w * t).as_matrix()

    audit = PredictionAudit(1)
    for k in range(100):
        now = k * dt
        taken = round((now - delay) / dt) * dt  # the newest sample that has arrived
        p, r = state(taken)
        held = TeamMeasurement(p[None], v[None], np.zeros((1, 3)), r[None], w[None])
        act = now + delay
        h = horizons_s(act, np.array([taken]))
        audit.observe(p[None], v[None], np.array([taken]), r[None], w[None], np.array([taken]))
        audit.record(act, predict(held, h, h), held, h)
    f = audit.figures(0)
    # THEN every prediction whose act time a sample has reached (all but the last ~10) was exact,
    # while the held samples were 100 ms (0.2 m, 0.1 rad) behind
    assert 85 <= f.resolved <= 90
    assert f.position_m.max() < 1e-9 and f.attitude_rad.max() < 1e-9
    assert np.allclose(f.position_held_m, 0.2) and np.allclose(f.attitude_held_rad, 0.1)
    assert np.allclose(f.horizon_s, 0.1)


def test_the_audit_skips_act_times_that_no_sample_came_near():
    # a prediction to t = 1 s, then samples taken at 0.9 s and 1.5 s (a gap: lost packets):
    # nothing within RESOLVE_WITHIN_S of the act time, so nothing is counted
    audit = PredictionAudit(1)
    m = TeamMeasurement(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)), np.eye(3)[None],
                        np.zeros((1, 3)))
    audit.record(1.0, m, m, np.array([0.1]))
    for taken in (0.9, 1.5):
        audit.observe(m.position_m, m.velocity_mps, np.array([taken]), m.rotation,
                      m.omega_radps, np.array([taken]))
    f = audit.figures(0)
    assert f.resolved == 0 and f.attitude_rad.size == 0
