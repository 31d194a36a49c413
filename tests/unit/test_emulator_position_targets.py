"""SET_POSITION_TARGET_LOCAL_NED as PX4 (setpoints.py) and ArduCopter (ardupilot_targets.py)
read it, and the one local-NED <-> team-ENU conversion (frames.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vehicle_emulator.autopilots.ardupilot.targets import guided_position_target
from vehicle_emulator.autopilots.demand import PositionTarget
from vehicle_emulator.autopilots.setpoints import (
    PositionTargetFields,
    from_position_target_local_ned,
)
from vehicle_emulator.physics import frames

VEL, ACC, YAW, YAW_RATE = 8 | 16 | 32, 64 | 128 | 256, 1024, 2048
POS = 1 | 2 | 4
POSITION_ONLY = VEL | ACC | YAW_RATE  # 2552: x, y, z and yaw
VELOCITY_ONLY = POS | ACC | YAW | YAW_RATE
ORIGIN = (4.0, -3.0, 0.0)  # the vehicle's local NED zero in the team frame
HERE = (5.0, -1.0, 10.0)  # the vehicle now (team ENU)
HEADING = math.pi / 2  # ENU yaw: facing north (NED yaw 0)


def fields(mask, frame=1, pos=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), acc=(0.0, 0.0, 0.0),
           yaw=0.0, yaw_rate=0.0) -> PositionTargetFields:
    return PositionTargetFields(mask, frame, pos, vel, acc, yaw, yaw_rate)


finite = st.floats(-1e4, 1e4, allow_nan=False)


@given(st.tuples(finite, finite, finite), st.tuples(finite, finite, finite))
def test_local_ned_and_team_enu_round_trip(p, origin):
    ned = frames.local_ned_from_enu(np.array(p), origin)
    assert np.allclose(frames.enu_from_local_ned(ned, origin), p)


def test_local_ned_is_relative_to_the_vehicles_origin():
    # GIVEN an origin at (4, -3, 0) ENU WHEN a point 2 m north, 1 m east, 5 m up of it
    # THEN it is at (5, -1, 5) in the team frame; headings map NED <-> ENU
    assert np.allclose(frames.enu_from_local_ned(np.array([2.0, 1.0, -5.0]), ORIGIN), [5, -1, 5])
    assert frames.yaw_enu_from_yaw_ned(0.0) == pytest.approx(math.pi / 2)
    assert frames.yaw_enu_from_yaw_ned(math.pi) == pytest.approx(-math.pi / 2)
    assert frames.yaw_ned_from_yaw_enu(frames.yaw_enu_from_yaw_ned(0.3)) == pytest.approx(0.3)


def test_px4_position_and_yaw_in_the_local_frame():
    # GIVEN x 2 north, y 1 east, z -12 (12 m up), yaw 90 deg (east), velocities ignored
    d = from_position_target_local_ned(
        fields(POSITION_ONLY, pos=(2.0, 1.0, -12.0), vel=(9, 9, 9), yaw=math.pi / 2),
        ORIGIN, HERE, HEADING)
    # THEN the onboard controller holds (5, -1, 12) ENU on all axes facing east (ENU yaw 0)
    assert d.setpoint == PositionTarget((5.0, -1.0, 12.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0),
                                        pytest.approx(0.0))


def test_px4_velocity_alone_and_per_axis_mixes():
    d = from_position_target_local_ned(fields(VELOCITY_ONLY, vel=(1.0, 2.0, -0.5)), ORIGIN,
                                       HERE, HEADING)
    assert d.setpoint.mask == (0.0, 0.0, 0.0)
    assert d.setpoint.velocity_ff_enu_mps == (2.0, 1.0, 0.5)
    assert d.setpoint.yaw_enu_rad == HEADING  # yaw ignored: the heading is kept
    # PX4 reads each axis: x, y position, z velocity (z and vx, vy ignored)
    d = from_position_target_local_ned(
        fields(4 | 8 | 16 | ACC | YAW | YAW_RATE, pos=(0.0, 0.0, -99.0), vel=(0, 0, -1.0)),
        ORIGIN, HERE, HEADING)
    assert d.setpoint.mask == (1.0, 1.0, 0.0)
    assert d.setpoint.position_enu_m[:2] == (4.0, -3.0)
    assert d.setpoint.velocity_ff_enu_mps == (0.0, 0.0, 1.0)
    # a NaN in a field that is not ignored counts as not set (PX4's isAllNan)
    d = from_position_target_local_ned(
        fields(VEL | ACC | YAW | YAW_RATE, pos=(1.0, math.nan, -2.0)), ORIGIN, HERE, HEADING)
    assert d.setpoint.mask == (0.0, 1.0, 1.0)


def test_px4_body_frame_velocity_is_rotated_by_the_heading():
    # GIVEN heading east (ENU yaw 0) WHEN 1 m/s forward in MAV_FRAME_BODY_NED THEN east
    d = from_position_target_local_ned(fields(POS | ACC | YAW | YAW_RATE, frame=8,
                                              vel=(1.0, 0.0, 0.0)), ORIGIN, HERE, 0.0)
    assert np.allclose(d.setpoint.velocity_ff_enu_mps, (1.0, 0.0, 0.0))
    assert d.setpoint.mask == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("f, text", [
    (fields(POS | VEL | ACC | YAW | YAW_RATE), "SET_POSITION_TARGET_LOCAL_NED invalid"),
    (fields(POSITION_ONLY, frame=7), "SET_POSITION_TARGET_LOCAL_NED coordinate frame 7 "
                                     "unsupported"),
    (fields(POS | VEL | 512), "SET_POSITION_TARGET_LOCAL_NED force not supported"),
    (fields(POSITION_ONLY, pos=(math.inf, 0, 0)), "position target not finite"),
])
def test_px4_refusals_name_the_reason(f, text):
    d = from_position_target_local_ned(f, ORIGIN, HERE, HEADING)
    assert d.setpoint is None and d.rejected == text


def test_ardupilot_position_velocity_and_offsets():
    # GIVEN ArduCopter's reading WHEN position + velocity in LOCAL_NED THEN both, not timed out
    target, velocity_only = guided_position_target(
        fields(ACC | YAW | YAW_RATE, pos=(2.0, 1.0, -12.0), vel=(0.5, 0, 0)), ORIGIN, HERE,
        HEADING)
    assert target.position_enu_m == (5.0, -1.0, 12.0) and not velocity_only
    assert target.velocity_ff_enu_mps == (0.0, 0.5, 0.0)
    # any one ignore bit ignores the whole vector (ArduPilot), unlike PX4
    target, velocity_only = guided_position_target(
        fields(4 | ACC | YAW | YAW_RATE, pos=(2.0, 1.0, -12.0), vel=(0.5, 0, 0)), ORIGIN, HERE,
        HEADING)
    assert target.mask == (0.0, 0.0, 0.0) and velocity_only
    # LOCAL_OFFSET_NED is relative to the vehicle; BODY_NED also rotated by the heading
    target, _ = guided_position_target(fields(POSITION_ONLY, frame=7, pos=(1.0, 0.0, 0.0)),
                                       ORIGIN, HERE, HEADING)
    assert np.allclose(target.position_enu_m, (5.0, 0.0, 10.0))
    target, _ = guided_position_target(fields(POSITION_ONLY, frame=8, pos=(1.0, 0.0, 0.0)),
                                       ORIGIN, HERE, 0.0)  # facing east
    assert np.allclose(target.position_enu_m, (6.0, -1.0, 10.0))


@pytest.mark.parametrize("f", [
    fields(POS | VEL | ACC | YAW | YAW_RATE),  # nothing
    fields(POSITION_ONLY, frame=3),  # not a local frame
    fields(POS | VEL | 512),  # force
    fields(VELOCITY_ONLY, vel=(math.nan, 0, 0)),  # not sane
])
def test_ardupilot_invalid_targets_stop_the_vehicle(f):
    assert guided_position_target(f, ORIGIN, HERE, HEADING) == (None, False)
