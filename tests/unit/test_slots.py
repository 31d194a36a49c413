"""Position mode's slot trajectory (gcs/control/slots.py) against closed forms, the team file's
own evaluation of v_r and numerical integration; no clock, no sockets."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from gcs.config import load_team
from gcs.config.schema import AxisReference, Cosine, ReferenceVelocity
from gcs.control.slots import FormationSlots, formation_centre_m, reference_displacement_m

ROOT = Path(__file__).resolve().parents[2]
SQUARE4 = load_team(ROOT / "configs" / "square4.yaml")
OFFSETS = SQUARE4.offsets_enu_m()
STARTS = SQUARE4.initial_positions_enu_m()
#: a reference with a constant and phases on every axis, and axes of different lengths (the
#: zero padding of as_arrays)
WAVY = ReferenceVelocity(
    AxisReference(0.1, (Cosine(0.3, 23.0), Cosine(-0.2, 7.0, 0.4))),
    AxisReference(-0.05, (Cosine(0.5, 11.5, 1.2),)),
    AxisReference(0.2, ()),
)


def test_scenario_one_slots_move_with_the_closed_form_of_its_reference():
    # GIVEN Scenario I's v_r: x 0.3 cos(2 pi t / 23), y 0.3 cos(2 pi t / 11.5), z 0.2 m/s
    slots = FormationSlots.start(STARTS, OFFSETS, SQUARE4.reference_velocity.as_arrays())
    # THEN c(0) is the mean of p_i(0) - theta_i over the four starts, by hand:
    # (2, 2, 9), (1, -2, 11), (-3, -2, 12), (1, 1, 8) -> (0.25, -0.25, 10)
    np.testing.assert_allclose(slots.centre0_enu_m, [0.25, -0.25, 10.0], atol=1e-12)
    # AND at t = 5.75 s (a quarter of x's period, half of y's) the centre has moved by
    # 0.3 * 23 / (2 pi) in x, 0.3 * 11.5 / (2 pi) * sin(pi) = 0 in y, 0.2 * 5.75 in z
    at = slots.at(5.75)
    moved = np.array([0.3 * 23.0 / (2.0 * math.pi), 0.0, 1.15])
    np.testing.assert_allclose(at.position_enu_m, [0.25, -0.25, 10.0] + moved + OFFSETS,
                               atol=1e-12)
    # AND the feed-forward is v_r(5.75) = (0, -0.3, 0.2) and v_r'(5.75) = (-0.3 2 pi / 23, 0, 0)
    np.testing.assert_allclose(at.velocity_enu_mps, [0.0, -0.3, 0.2], atol=1e-12)
    np.testing.assert_allclose(at.acceleration_enu_mps2, [-0.3 * 2.0 * math.pi / 23.0, 0.0, 0.0],
                               atol=1e-12)


@pytest.mark.parametrize("t_s", [0.0, 0.37, 5.0, 23.0, 61.3])
def test_the_displacement_is_the_integral_of_v_r(t_s):
    # GIVEN v_r evaluated by the team file's own numpy code (ReferenceVelocity.evaluate)
    reference = WAVY.as_arrays()
    # THEN the closed-form displacement equals a numerical integral of it, axis by axis
    expected = [quad(lambda s, k=k: WAVY.evaluate(s)[k], 0.0, t_s, epsabs=1e-12)[0]
                for k in range(3)]
    np.testing.assert_allclose(reference_displacement_m(t_s, reference), expected, atol=1e-9)


@pytest.mark.parametrize("t_s", [0.0, 3.3, 17.0, 44.4])
def test_velocity_and_acceleration_are_v_r_and_its_derivative_and_match_the_positions(t_s):
    slots = FormationSlots.start(STARTS, OFFSETS, WAVY.as_arrays())
    at = slots.at(t_s)
    # THEN the feed-forward is the team file's v_r and v_r' (not the code under test's)
    np.testing.assert_allclose(at.velocity_enu_mps, WAVY.evaluate(t_s), atol=1e-12)
    np.testing.assert_allclose(at.acceleration_enu_mps2, WAVY.evaluate(t_s, 1), atol=1e-12)
    # AND it is what the slots actually do: central differences of positions and velocities
    h = 1e-4
    ahead, behind = slots.at(t_s + h), slots.at(t_s - h)
    v_fd = (ahead.position_enu_m - behind.position_enu_m) / (2.0 * h)
    np.testing.assert_allclose(v_fd, np.tile(at.velocity_enu_mps, (4, 1)), atol=1e-7)
    a_fd = (ahead.velocity_enu_mps - behind.velocity_enu_mps) / (2.0 * h)
    np.testing.assert_allclose(a_fd, at.acceleration_enu_mps2, atol=1e-7)


def test_a_team_already_in_formation_is_sent_where_it_is():
    # GIVEN four vehicles exactly in their slots about (3, -1, 12)
    here = np.array([3.0, -1.0, 12.0]) + OFFSETS
    slots = FormationSlots.start(here, OFFSETS, SQUARE4.reference_velocity.as_arrays())
    # THEN at t = 0 each slot is the vehicle's own position: nobody is asked to move
    np.testing.assert_allclose(slots.at(0.0).position_enu_m, here, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-50.0, 50.0), min_size=12, max_size=12),
       st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3),
       st.floats(0.0, 120.0))
def test_slots_keep_the_shape_and_move_with_the_team(positions, shift, t_s):
    p = np.array(positions).reshape(4, 3)
    reference = SQUARE4.reference_velocity.as_arrays()
    slots = FormationSlots.start(p, OFFSETS, reference).at(t_s)
    # THEN the slots form the formation's shape exactly: slot_i - slot_j = theta_i - theta_j
    shape = slots.position_enu_m - slots.position_enu_m[0]
    np.testing.assert_allclose(shape, OFFSETS - OFFSETS[0], atol=1e-9)
    # AND moving the whole team moves every slot by as much (translation invariance)
    moved = FormationSlots.start(p + np.array(shift), OFFSETS, reference).at(t_s)
    np.testing.assert_allclose(moved.position_enu_m - slots.position_enu_m,
                               np.tile(shift, (4, 1)), atol=1e-9)
    # AND the centre is the mean of the positions less their offsets
    np.testing.assert_allclose(formation_centre_m(p, OFFSETS),
                               np.mean(p - OFFSETS, axis=0), atol=1e-12)


def test_a_position_that_is_not_finite_is_refused_naming_its_row():
    p = STARTS.copy()
    p[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"the positions of rows \[2\] are not finite"):
        formation_centre_m(p, OFFSETS)
    with pytest.raises(ValueError, match=r"must both be \(n, 3\)"):
        formation_centre_m(STARTS[:3], OFFSETS)
