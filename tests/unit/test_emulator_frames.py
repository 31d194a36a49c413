"""vehicle_emulator.physics.frames: ENU/FLU <-> NED/FRD and quaternion conversions (round trips)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle_emulator.physics import frames

finite = st.floats(-1e3, 1e3, allow_nan=False)
vec3 = st.tuples(finite, finite, finite)
quat = st.tuples(*(st.floats(-1, 1, allow_nan=False) for _ in range(4))).filter(
    lambda q: math.sqrt(sum(x * x for x in q)) > 0.1
)


@given(vec3)
def test_vector_round_trips(v):
    a = np.array(v)
    assert np.allclose(frames.ned_to_enu(frames.enu_to_ned(a)), a)
    assert np.allclose(frames.frd_to_flu(frames.flu_to_frd(a)), a)


@settings(max_examples=200, deadline=None)
@given(quat)
def test_rotation_quaternion_and_frame_round_trips(q):
    r = frames.rotation_from_quaternion(np.array(q))
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.linalg.det(r) > 0
    q2 = frames.quaternion_from_rotation(r)
    assert np.allclose(frames.rotation_from_quaternion(q2), r, atol=1e-12)
    assert q2[0] >= 0
    r_ned = frames.rotation_ned_frd_from_enu_flu(r)
    assert np.allclose(frames.rotation_enu_flu_from_ned_frd(r_ned), r, atol=1e-12)
    # the numba quaternion agrees with the numpy one
    assert np.allclose(frames.quat_from_matrix(r), q2, atol=1e-12)


def test_known_attitudes():
    # GIVEN a level vehicle facing north (ENU yaw +90 deg) THEN NED/FRD attitude is identity
    r_enu = frames.rotation_enu_flu_from_yaw_ned(0.0)
    assert np.allclose(frames.rotation_ned_frd_from_enu_flu(r_enu), np.eye(3))
    assert np.allclose(frames.quaternion_from_rotation(np.eye(3)), [1, 0, 0, 0])
    # facing east (ENU identity) is NED yaw +90 deg
    eul = frames.euler_ned_frd_from_rotation(frames.rotation_ned_frd_from_enu_flu(np.eye(3)))
    assert np.allclose(eul, [0.0, 0.0, math.pi / 2])
    assert frames.yaw_ned_from_rotation_enu_flu(np.eye(3)) == math.pi / 2
    # FLU body +z (thrust) is FRD -z; ENU up is NED -down
    assert np.allclose(frames.flu_to_frd(np.array([0, 0, 1.0])), [0, 0, -1])
    assert np.allclose(frames.enu_to_ned(np.array([1.0, 2.0, 3.0])), [2, 1, -3])


@settings(max_examples=50, deadline=None)
@given(quat, vec3, vec3)
def test_fleet_kernel_matches_the_numpy_conversions(q, p, v):
    r = frames.rotation_from_quaternion(np.array(q))[None]
    pos, vel = np.array([p]), np.array([v])
    w = np.array([[0.1, -0.2, 0.3]])
    sf = np.array([[0.0, 0.0, 9.81]])
    out = {
        k: np.empty(s)
        for k, s in [
            ("r", (1, 3, 3)),
            ("q", (1, 4)),
            ("e", (1, 3)),
            ("w", (1, 3)),
            ("p", (1, 3)),
            ("v", (1, 3)),
            ("vb", (1, 3)),
            ("a", (1, 3)),
            ("qs", (1, 4)),
            ("rs", (1, 3)),
            ("y", (1,)),
        ]
    }
    none = np.zeros((0, 3))
    frames.fleet_to_ned_frd(
        frames.Reported(r, w, pos, vel, sf),
        r,
        w,
        np.arange(1),
        np.zeros(0, dtype=np.int64),
        frames.TelemetryNoise(none, none, none, none, none),
        frames.NedFrd(*out.values()),
    )
    r_ned = frames.rotation_ned_frd_from_enu_flu(r)
    assert np.allclose(out["r"], r_ned)
    assert np.allclose(out["q"], frames.quaternion_from_rotation(r_ned))
    # angles compare modulo 2 pi: at roll = 180 deg, atan2(+-0, -1) is +-pi by the sign of a zero
    wrapped = np.angle(np.exp(1j * (out["e"] - frames.euler_ned_frd_from_rotation(r_ned))))
    assert np.allclose(wrapped, 0.0)
    assert np.allclose(out["p"], frames.enu_to_ned(pos))
    assert np.allclose(out["vb"][0], r_ned[0].T @ frames.enu_to_ned(vel)[0])
    assert np.allclose(out["a"], [[0, 0, -9.81]])
