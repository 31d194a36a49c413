"""SET_ATTITUDE_TARGET / SET_ACTUATOR_CONTROL_TARGET decoding with PX4's type_mask rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vehicle_emulator.autopilots.demand import ActuatorSetpoint, AttitudeSetpoint, RatesSetpoint
from vehicle_emulator.autopilots.setpoints import from_actuator_control_target, from_attitude_target

LEVEL_NORTH = [1.0, 0.0, 0.0, 0.0]


def test_rates_and_thrust_type_mask_128():
    d = from_attitude_target(128, LEVEL_NORTH, (0.1, 0.2, 0.3), 0.4)
    assert d.setpoint == RatesSetpoint((0.1, -0.2, -0.3), 0.4)  # FRD -> FLU


def test_attitude_and_thrust_type_mask_7():
    d = from_attitude_target(7, LEVEL_NORTH, (9.0, 9.0, 9.0), 0.4)
    assert isinstance(d.setpoint, AttitudeSetpoint)
    # identity in NED/FRD (level, north) is ENU yaw +90 deg
    assert np.allclose(d.setpoint.rotation_enu_flu, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert d.setpoint.yaw_rate_ff_flu_radps == 0.0 and d.setpoint.thrust_norm == 0.4


def test_attitude_wins_and_yaw_rate_is_a_feed_forward():
    d = from_attitude_target(0, LEVEL_NORTH, (1.0, 1.0, 0.5), 0.4)
    assert isinstance(d.setpoint, AttitudeSetpoint)
    assert d.setpoint.yaw_rate_ff_flu_radps == -0.5


def test_rates_need_roll_and_pitch():
    assert from_attitude_target(128 | 1, LEVEL_NORTH, (0, 0, 0), 0.4).setpoint is None
    d = from_attitude_target(128 | 4, LEVEL_NORTH, (0.1, 0.2, 0.3), 0.4)
    assert d.setpoint == RatesSetpoint((0.1, -0.2, -0.0), 0.4)


def test_throttle_ignore_keeps_the_previous_thrust():
    assert from_attitude_target(128 | 64, LEVEL_NORTH, (0, 0, 0), 0.9).setpoint is None
    d = from_attitude_target(128 | 64, LEVEL_NORTH, (0, 0, 0), 0.9, previous_thrust=0.3)
    assert d.setpoint.thrust_norm == 0.3


def test_thrust_body_is_used_only_in_the_attitude_branch():
    d = from_attitude_target(32, LEVEL_NORTH, (0, 0, 0), 0.9, thrust_body=(0, 0, -0.25))
    assert d.setpoint.thrust_norm == 0.25
    d = from_attitude_target(128 | 32, LEVEL_NORTH, (0, 0, 0), 0.9, thrust_body=(0, 0, -0.25))
    assert d.setpoint.thrust_norm == 0.9


@pytest.mark.parametrize(
    "fields, why",
    [
        (dict(type_mask=128, q=LEVEL_NORTH, rates=(math.nan, 0, 0), thrust=0.4), "rate"),
        (dict(type_mask=0, q=[math.nan, 0, 0, 0], rates=(0, 0, 0), thrust=0.4), "quaternion"),
        (dict(type_mask=0, q=[0.1, 0, 0, 0], rates=(0, 0, 0), thrust=0.4), "norm"),
        (dict(type_mask=128, q=LEVEL_NORTH, rates=(0, 0, 0), thrust=math.inf), "thrust"),
    ],
)
def test_non_finite_or_absurd_fields_are_rejected(fields, why):
    d = from_attitude_target(fields["type_mask"], fields["q"], fields["rates"], fields["thrust"])
    assert d.setpoint is None and why in d.rejected


def test_out_of_range_values_are_clamped_and_flagged():
    d = from_attitude_target(128, LEVEL_NORTH, (50.0, 0, 0), 1.7)
    assert d.clamped and d.setpoint == RatesSetpoint((10.0, -0.0, -0.0), 1.0)


def test_actuator_group_0():
    d = from_actuator_control_target(0, [0.1, 0.2, -0.3, 0.5, 0, 0, 0, 0])
    assert d.setpoint == ActuatorSetpoint((0.1, -0.2, 0.3), 0.5)
    assert from_actuator_control_target(1, [0.0] * 8).setpoint is None
    assert from_actuator_control_target(0, [math.nan] * 8).setpoint is None
    assert from_actuator_control_target(0, [3, 0, 0, 2, 0, 0, 0, 0]).clamped
