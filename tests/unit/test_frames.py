"""Frame and quaternion conversions between MAVLink NED/FRD and the app's ENU/FLU."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from pymavlink.quaternion import QuaternionBase
from scipy.spatial.transform import Rotation

from gcs import frames

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, (3,), elements=finite)
vecs = arrays(np.float64, st.tuples(st.integers(1, 8), st.just(3)), elements=finite)


@st.composite
def unit_quats(draw: st.DrawFn) -> np.ndarray:
    q = draw(arrays(np.float64, (4,), elements=st.floats(-1.0, 1.0)))
    if np.linalg.norm(q) < 0.1:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    return q / np.linalg.norm(q)


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- known values ------------------------------------------------------------------------------


def test_vectors_swap_axes_and_flip_z() -> None:
    # GIVEN east 1, north 2, up 3 WHEN converted to NED THEN north 2, east 1, down -3
    np.testing.assert_array_equal(frames.ned_from_enu([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])
    np.testing.assert_array_equal(frames.enu_from_ned([2.0, 1.0, -3.0]), [1.0, 2.0, 3.0])
    # AND body FLU (1, 2, 3) is FRD (1, -2, -3)
    np.testing.assert_array_equal(frames.frd_from_flu([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])
    np.testing.assert_array_equal(frames.flu_from_frd([1.0, -2.0, -3.0]), [1.0, 2.0, 3.0])


def test_level_hover_accelerometer_reads_up_in_flu() -> None:
    # GIVEN a level vehicle's FRD specific force (0, 0, -g) THEN in FLU it points up
    np.testing.assert_array_equal(frames.flu_from_frd([0.0, 0.0, -9.81]), [0.0, 0.0, 9.81])


def test_facing_east_is_identity_in_enu_and_yaw_90_in_ned() -> None:
    # GIVEN body x along east (R_enu_flu = I)
    # WHEN converted to MAVLink
    r_ned_frd = frames.rotation_ned_frd_from_enu_flu(np.eye(3))
    q = frames.mavlink_quat_from_rotation_enu_flu(np.eye(3))
    # THEN it is a 90 deg yaw about NED down, quaternion (cos 45, 0, 0, sin 45)
    np.testing.assert_allclose(r_ned_frd, rot_z(math.pi / 2), atol=1e-15)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(q, [s, 0.0, 0.0, s], atol=1e-15)


@pytest.mark.parametrize("yaw_ned_deg", [-170.0, -90.0, -30.0, 0.0, 45.0, 90.0, 135.0, 179.0])
def test_known_yaw_matches_textbook_and_pymavlink(yaw_ned_deg: float) -> None:
    # GIVEN a heading psi (NED, clockwise from north seen from above)
    psi = math.radians(yaw_ned_deg)
    textbook_q = np.array([math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)])
    if textbook_q[0] < 0:
        textbook_q = -textbook_q
    # WHEN the app attitude is yaw (90 deg - psi) about ENU up
    r_enu_flu = rot_z(math.pi / 2 - psi)
    q = frames.mavlink_quat_from_rotation_enu_flu(r_enu_flu)
    # THEN the MAVLink quaternion is the textbook yaw quaternion and pymavlink's
    np.testing.assert_allclose(q, textbook_q, atol=1e-12)
    pm = np.array(QuaternionBase([0.0, 0.0, psi]).q)
    np.testing.assert_allclose(q, pm if pm[0] >= 0 else -pm, atol=1e-12)
    # AND decoding it gives the attitude back
    np.testing.assert_allclose(frames.rotation_enu_flu_from_mavlink_quat(q), r_enu_flu,
                               atol=1e-12)


@pytest.mark.parametrize("euler", [(0.1, -0.2, 0.3), (-1.0, 0.5, 2.5), (0.0, 1.2, -3.0)])
def test_euler_matches_pymavlink_dcm_and_quaternion(euler: tuple[float, float, float]) -> None:
    # GIVEN MAVLink ATTITUDE roll, pitch, yaw
    pm = QuaternionBase(list(euler))
    # WHEN converted THEN the matrix equals pymavlink's DCM and the quaternion its q
    r = frames.rotation_ned_frd_from_euler(*euler)
    np.testing.assert_allclose(r, np.array(pm.dcm), atol=1e-12)
    q_pm = np.array(pm.q)
    np.testing.assert_allclose(frames.quat_wxyz_from_rotation(r), q_pm if q_pm[0] >= 0 else -q_pm,
                               atol=1e-12)
    # AND the ENU/FLU attitude from Euler equals the one from the quaternion
    np.testing.assert_allclose(frames.rotation_enu_flu_from_mavlink_euler(*euler),
                               frames.rotation_enu_flu_from_mavlink_quat(q_pm), atol=1e-12)


def test_quaternion_order_helpers_match_scipy() -> None:
    q_wxyz = np.array([0.8, 0.2, -0.4, 0.4]) / np.linalg.norm([0.8, 0.2, -0.4, 0.4])
    q_xyzw = frames.quat_xyzw_from_wxyz(q_wxyz)
    np.testing.assert_allclose(Rotation.from_quat(q_xyzw).as_matrix(),
                               frames.rotation_from_quat_wxyz(q_wxyz), atol=1e-12)
    np.testing.assert_array_equal(frames.quat_wxyz_from_xyzw(q_xyzw), q_wxyz)


def test_shape_errors_name_the_argument() -> None:
    with pytest.raises(ValueError, match=r"v_enu: expected shape \(\.\.\., 3\), got \(4,\)"):
        frames.ned_from_enu([1.0, 2.0, 3.0, 4.0])
    with pytest.raises(ValueError, match=r"rotation_enu_flu: expected shape \(\.\.\., 3, 3\)"):
        frames.rotation_ned_frd_from_enu_flu(np.eye(2))
    with pytest.raises(ValueError, match="q_wxyz: expected finite non-zero"):
        frames.rotation_from_quat_wxyz([0.0, 0.0, 0.0, 0.0])


def test_is_rotation() -> None:
    assert frames.is_rotation(rot_z(0.3))
    assert not frames.is_rotation(np.diag([1.0, 1.0, -1.0]))  # reflection
    assert not frames.is_rotation(2.0 * np.eye(3))
    assert not frames.is_rotation(np.full((3, 3), np.nan))
    np.testing.assert_array_equal(frames.is_rotation(np.stack([np.eye(3), 2 * np.eye(3)])),
                                  [True, False])


def test_yaw_ned_from_enu_turns_east_anticlockwise_into_north_clockwise() -> None:
    # GIVEN headings east, north, west and south as ENU yaws (from east, anticlockwise)
    yaw_enu = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    # THEN their NED yaws (from north, clockwise) are 90, 0, -90 and 180 (= -180) deg
    np.testing.assert_allclose(frames.yaw_ned_from_enu(yaw_enu),
                               [math.pi / 2, 0.0, -math.pi / 2, -math.pi], atol=1e-15)

# --- properties --------------------------------------------------------------------------------


@given(vecs)
def test_vector_round_trips(v: np.ndarray) -> None:
    np.testing.assert_array_equal(frames.enu_from_ned(frames.ned_from_enu(v)), v)
    np.testing.assert_array_equal(frames.flu_from_frd(frames.frd_from_flu(v)), v)


@given(unit_quats())
def test_quaternion_matrix_round_trip(q: np.ndarray) -> None:
    r = frames.rotation_from_quat_wxyz(q)
    assert frames.is_rotation(r, tol=1e-9)
    q2 = frames.quat_wxyz_from_rotation(r)
    assert q2[0] >= 0.0
    # q and -q are the same rotation; the returned one has w >= 0 (either sign when w == 0)
    assert np.allclose(q2, q, atol=1e-9) or np.allclose(q2, -q, atol=1e-9)
    np.testing.assert_allclose(frames.rotation_from_quat_wxyz(q2), r, atol=1e-9)


@given(unit_quats(), vec3)
def test_mavlink_attitude_maps_the_same_physical_vector(q: np.ndarray, v_flu: np.ndarray) -> None:
    # GIVEN an app attitude and a body vector in FLU
    r_enu_flu = frames.rotation_from_quat_wxyz(q)
    # WHEN the attitude goes to MAVLink and back
    q_mav = frames.mavlink_quat_from_rotation_enu_flu(r_enu_flu)
    r_ned_frd = frames.rotation_from_quat_wxyz(q_mav)
    # THEN rotating the FRD vector in NED is the same world vector as rotating FLU in ENU
    np.testing.assert_allclose(r_ned_frd @ frames.frd_from_flu(v_flu),
                               frames.ned_from_enu(r_enu_flu @ v_flu), atol=1e-9)
    np.testing.assert_allclose(frames.rotation_enu_flu_from_mavlink_quat(q_mav), r_enu_flu,
                               atol=1e-9)


@settings(max_examples=30)
@given(st.lists(unit_quats(), min_size=1, max_size=6))
def test_batched_equals_one_by_one(qs: list[np.ndarray]) -> None:
    q = np.stack(qs)
    r = frames.rotation_enu_flu_from_mavlink_quat(q)
    assert r.shape == (len(qs), 3, 3)
    for i, qi in enumerate(qs):
        np.testing.assert_allclose(r[i], frames.rotation_enu_flu_from_mavlink_quat(qi), atol=1e-12)
    back = frames.mavlink_quat_from_rotation_enu_flu(r)
    for i in range(len(qs)):
        np.testing.assert_allclose(back[i], frames.mavlink_quat_from_rotation_enu_flu(r[i]),
                                   atol=1e-12)
    np.testing.assert_allclose(frames.rotation_ned_frd_from_enu_flu(
        frames.rotation_enu_flu_from_ned_frd(r)), r, atol=1e-15)


def test_attitude_conversions_are_the_matrix_products_p_r_f_for_any_stack():
    # GIVEN rotations stacked (2, 5) deep, and a single one
    rng = np.random.default_rng(11)
    stack = frames.rotation_from_quat_wxyz(rng.normal(size=(2, 5, 4)))
    for r in (stack, stack[1, 3]):
        # THEN both directions are exactly P R F (the row/column picks are only faster)
        want = frames.P_NED_ENU @ r @ frames.F_FRD_FLU
        assert np.array_equal(frames.rotation_enu_flu_from_ned_frd(r), want)
        assert np.array_equal(frames.rotation_ned_frd_from_enu_flu(r), want)
        assert np.array_equal(frames.rotation_ned_frd_from_enu_flu(
            frames.rotation_enu_flu_from_ned_frd(r)), r)
