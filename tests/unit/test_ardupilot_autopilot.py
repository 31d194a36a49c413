"""Pure ArduCopter logic (ardupilot.py, ardupilot_targets.py) against what ArduCopter 4.7.0-dev
SITL did in the recordings (../shared/data/sitl/README.md, ArduPilot sections 1-2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vehicle_emulator.autopilots.ardupilot.boot import BootTimeline
from vehicle_emulator.autopilots.ardupilot.logic import ArduCopter, CopterObservation
from vehicle_emulator.autopilots.ardupilot.modes import Mode
from vehicle_emulator.autopilots.ardupilot.targets import (
    climb_rate_of_thrust,
    guided_attitude_target,
)
from vehicle_emulator.autopilots.demand import (
    AttitudeSetpoint,
    Idle,
    MavResult,
    MotorsOff,
    PositionTarget,
    RatesSetpoint,
    Severity,
)
from vehicle_emulator.config.params import ParamStore

GROUND = CopterObservation((1.0, 2.0, 0.0), (0.0, 0.0, 0.0), 0.3, True)
AIR = CopterObservation((1.0, 2.0, 5.0), (0.0, 0.0, 0.0), 0.3, False)
BOOTED_S = 45.0  # past the recorded boot timeline (position estimate at 41.63 s)


def params(**values: float) -> ParamStore:
    p = ParamStore.for_family("ardupilot")
    p.set("MOT_THST_HOVER", 0.35)
    for name, value in values.items():
        p.set(name, value)
    return p


def texts(ap: ArduCopter) -> list[str]:
    out, ap.events[:] = [t for _, t in ap.events], []
    return out


def angle(thrust: float, use_thrust: bool = True):
    return guided_attitude_target(128, [1, 0, 0, 0], (0, 0, 0), thrust, use_thrust, 2.5, 1.5)


@pytest.mark.parametrize("t_s, reasons", [
    (1.02, ["System not initialised"]),
    (3.02, ["Accels inconsistent", "EKF attitude is bad", "AHRS: not using configured AHRS type"]),
    (5.02, ["Accels inconsistent", "EKF attitude is bad", "AHRS: EKF3 still initialising"]),
    (13.02, ["Accels inconsistent"]),
    (23.02, ["Gyros inconsistent"]),
    (24.02, []),  # recorded: "Arming motors" at attempt 24
])
def test_the_recorded_boot_timeline_of_arming_refusals_in_stabilize(t_s, reasons):
    ap = ArduCopter.start(1, params(), 0.0, GROUND)
    result = ap.arm(t_s, GROUND, True)
    expected = [f"Arm: {r}" for r in reasons] or ["Arming motors"]
    assert texts(ap) == expected
    assert result is (MavResult.FAILED if reasons else MavResult.ACCEPTED)
    assert all(s is Severity.CRITICAL for s, _ in ap.events)


def test_guided_needs_the_position_estimate_and_the_time_scale_shortens_the_boot():
    ap = ArduCopter.start(1, params(), 0.0, GROUND)
    assert ap.set_mode(30.0, GROUND, Mode.GUIDED) is MavResult.ACCEPTED  # disarmed: accepted
    assert ap.arm(41.25, GROUND, True) is MavResult.FAILED  # recorded 12 attempts to 41.25 s
    assert texts(ap) == ["Arm: Need Position Estimate"]
    assert ap.arm(42.25, GROUND, True) is MavResult.ACCEPTED
    # EMU_BOOT_SCALE 0.1: the same timeline ten times faster; 0: booted at once
    fast = ArduCopter.start(1, params(EMU_BOOT_SCALE=0.1), 0.0, GROUND)
    assert fast.arm_failures(2.0) == ["Gyros inconsistent"] and fast.position_ok(4.2)
    assert ArduCopter.start(1, params(EMU_BOOT_SCALE=0), 0.0, GROUND).arm_failures(0.0) == []


def test_boot_texts_origin_messages_and_the_prearm_report():
    ap = ArduCopter.start(1, params(), 0.0, GROUND)
    ap.set_mode(25.0, GROUND, Mode.GUIDED)
    for t in np.arange(0.0, 42.0, 0.02):
        ap.tick(float(t), GROUND)
        if ap.requests:
            assert t == pytest.approx(BootTimeline.ORIGIN_S, abs=0.03)
            assert ap.requests == [49, 242]  # GPS_GLOBAL_ORIGIN, HOME_POSITION
            ap.requests.clear()
    out = texts(ap)
    assert out[:4] == ["Calibrating barometer", "Barometer 1 calibration complete",
                       "Barometer 2 calibration complete", "ArduPilot Ready"]
    assert "PreArm: Need Position Estimate" in out  # recorded at 29.46 s, in GUIDED
    assert out[-2:] == ["EKF3 IMU0 is using GPS", "EKF3 IMU1 is using GPS"]


def test_heartbeat_base_mode_and_system_status_as_recorded():
    ap = ArduCopter.start(1, params(), 0.0, GROUND)
    assert (ap.base_mode(0.5), ap.system_status(0.5), ap.custom_mode) == (89, 1, 0)
    assert (ap.base_mode(BOOTED_S), ap.system_status(BOOTED_S)) == (81, 3)  # STABILIZE
    for mode, base in ((Mode.GUIDED_NOGPS, 89), (Mode.GUIDED, 89), (Mode.BRAKE, 89),
                       (Mode.LAND, 89), (Mode.STABILIZE, 81)):
        ap.set_mode(BOOTED_S, GROUND, mode)
        assert (ap.custom_mode, ap.base_mode(BOOTED_S)) == (int(mode), base)
    ap.set_mode(BOOTED_S, GROUND, Mode.GUIDED)
    ap.arm(BOOTED_S, GROUND, True)
    assert (ap.base_mode(BOOTED_S), ap.system_status(BOOTED_S)) == (217, 3)  # armed, landed
    flying = ArduCopter.start(1, params(), 0.0, AIR)  # past boot, armed in GUIDED
    assert (flying.base_mode(0.0), flying.system_status(0.0), flying.mode) == (217, 4,
                                                                              Mode.GUIDED)
    flying.set_mode(0.0, AIR, Mode.GUIDED_NOGPS)
    assert flying.base_mode(0.0) == 209 and flying.first_offboard_s == 0.0


def test_mode_rules():
    ap = ArduCopter.start(1, params(), 0.0, GROUND)
    assert ap.set_mode(0.0, GROUND, 99) is MavResult.FAILED and texts(ap) == ["No such mode 99"]
    assert ap.set_mode(0.0, GROUND, Mode.AUTO) is MavResult.FAILED  # not emulated
    ap.arm(24.1, GROUND, True)  # STABILIZE, before the position estimate
    assert ap.set_mode(25.0, GROUND, Mode.GUIDED) is MavResult.FAILED
    assert texts(ap)[-1] == "Mode change to GUIDED failed: requires position"
    assert ap.set_mode(25.0, GROUND, Mode.GUIDED_NOGPS) is MavResult.ACCEPTED


def test_arming_checks_modes_and_force():
    ap = ArduCopter.start(1, params(EMU_BOOT_SCALE=0), 0.0, GROUND)
    for mode in (Mode.LAND, Mode.BRAKE):
        ap.set_mode(0.0, GROUND, mode)
        assert ap.arm(0.0, GROUND, True) is MavResult.FAILED
        assert texts(ap) == [f"Arm: {mode.name} mode not armable"]
    assert ap.arm(0.0, GROUND, True, magic=2989) is MavResult.ACCEPTED  # forced
    assert ap.arm(0.0, GROUND, True) is MavResult.ACCEPTED  # already armed
    flying = ArduCopter.start(1, params(), 0.0, AIR)
    assert flying.arm(0.0, AIR, False) is MavResult.FAILED and texts(flying) == []  # silent
    assert flying.arm(0.0, AIR, False, magic=21196) is MavResult.ACCEPTED
    assert texts(flying) == ["Disarming motors"] and isinstance(flying.demand, MotorsOff)


def test_guid_timeout_the_setpoint_lasts_exactly_three_seconds_then_level_and_hold():
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    ap.set_mode(0.0, AIR, Mode.GUIDED_NOGPS)
    sp = angle(0.4)
    assert ap.on_attitude_target(10.0, AIR, sp)
    for t in np.arange(10.0, 12.999, 0.02):
        ap.tick(float(t), AIR)
        assert ap.demand is sp.setpoint  # the thrust as sent, exactly
    ap.tick(13.02, AIR)
    assert isinstance(ap.demand, AttitudeSetpoint) and ap.demand is not sp.setpoint
    assert np.allclose(ap.demand.rotation_enu_flu[:, 2], [0, 0, 1])  # level
    assert ap.demand.thrust_norm == pytest.approx(0.35, abs=0.01)  # holds: hover
    assert ap.mode is Mode.GUIDED_NOGPS and texts(ap) == []


def test_setpoints_outside_the_guided_modes_are_ignored():
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    ap.set_mode(0.0, AIR, Mode.BRAKE)
    assert not ap.on_attitude_target(1.0, AIR, angle(0.9))
    ap.set_mode(1.0, AIR, Mode.GUIDED_NOGPS)  # starts without a setpoint: level, hold
    assert ap.setpoint is None and ap.demand.thrust_norm == pytest.approx(0.35, abs=0.01)
    assert not ap.on_position_target(1.0, AIR, PositionTarget((0, 0, 9)))  # GUIDED only


def test_thrust_is_a_climb_rate_unless_guid_options_bit_3():
    assert climb_rate_of_thrust(0.5, 2.5, 1.5) == 0.0
    assert climb_rate_of_thrust(1.0, 2.5, 1.5) == 2.5
    assert climb_rate_of_thrust(0.25, 2.5, 1.5) == -0.75
    climb = angle(0.75, use_thrust=False)
    assert climb.climb_rate_mps == 1.25 and climb.setpoint.thrust_norm == 0.0
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    ap.set_mode(0.0, AIR, Mode.GUIDED_NOGPS)
    ap.on_attitude_target(0.0, AIR, climb)
    assert isinstance(ap.demand, RatesSetpoint) and ap.demand.thrust_norm > 0.35  # climbing


@pytest.mark.parametrize("mask, q", [
    (128 | 64, [1, 0, 0, 0]),  # THROTTLE_IGNORE
    (0, [0.99, 0, 0, 0]),  # not unit length within 1e-3
    (128 | 1, [1, 0, 0, 0]),  # some rates ignored
])
def test_attitude_targets_arducopter_refuses(mask, q):
    assert guided_attitude_target(mask, q, (0, 0, 0), 0.4, True, 2.5, 1.5) is None


def test_an_invalid_target_stops_guided_and_is_ignored_by_guided_nogps():
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    ap.on_position_target(0.0, AIR, PositionTarget((5, 5, 5), (1, 0, 0), (0, 0, 0)), True)
    ap.on_attitude_target(0.1, AIR, None)
    assert ap.demand.velocity_ff_enu_mps == (0, 0, 0) and ap.demand.mask == (0, 0, 1)
    ap.set_mode(0.2, AIR, Mode.GUIDED_NOGPS)
    ap.on_attitude_target(0.3, AIR, angle(0.4))
    assert not ap.on_attitude_target(0.4, AIR, None) and ap.demand is ap.setpoint.setpoint


def test_a_velocity_target_times_out_after_guid_timeout():
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    target = PositionTarget(AIR.position_enu_m, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert ap.on_position_target(0.0, AIR, target, velocity_only=True)
    ap.tick(2.99, AIR)
    assert ap.demand is target
    ap.tick(3.01, AIR)
    assert ap.demand.velocity_ff_enu_mps == (0.0, 0.0, 0.0)


def test_takeoff_spools_up_then_climbs_and_landing_disarms_in_land():
    ap = ArduCopter.start(1, params(EMU_BOOT_SCALE=0), 0.0, GROUND)
    assert ap.takeoff(0.0, GROUND, 5.0) is MavResult.FAILED  # disarmed
    ap.set_mode(0.0, GROUND, Mode.GUIDED)
    ap.arm(0.0, GROUND, True)
    assert ap.takeoff(0.0, GROUND, 5.0) is MavResult.ACCEPTED
    ap.tick(2.4, GROUND)
    assert isinstance(ap.demand, Idle) and ap.landed_state() == 1  # spooling up (2.5 s)
    ap.tick(2.6, GROUND)
    assert isinstance(ap.demand, PositionTarget) and ap.landed_state() == 3
    # WHEN LAND in the air THEN it descends at LAND_SPEED and is LANDING
    ap.tick(10.0, AIR)
    ap.set_mode(10.0, AIR, Mode.LAND)
    assert ap.demand.velocity_ff_enu_mps == (0.0, 0.0, -0.5) and ap.landed_state() == 4
    for t in np.arange(20.0, 21.65, 0.02):  # touchdown at 20 s
        ap.tick(float(t), GROUND)
    assert ap.land_complete and ap.armed  # land detector 1.6 s, disarm 0.5 s later
    ap.tick(22.2, GROUND)
    assert not ap.armed and ap.mode is Mode.LAND and texts(ap)[-1] == "Disarming motors"
    assert ap.arm(23.0, GROUND, True) is MavResult.FAILED
    assert texts(ap) == ["Arm: LAND mode not armable"]


def test_disarm_delay_after_arming_without_takeoff():
    ap = ArduCopter.start(1, params(EMU_BOOT_SCALE=0), 0.0, GROUND)
    ap.arm(1.0, GROUND, True)
    ap.tick(10.9, GROUND)
    assert ap.armed
    ap.tick(11.01, GROUND)
    assert not ap.armed and texts(ap)[-1] == "Disarming motors"


def test_guided_nogps_on_the_ground_idles_until_auto_armed():
    # GIVEN armed on the ground in GUIDED_NOGPS without a takeoff (ArduPilot: not auto-armed)
    ap = ArduCopter.start(1, params(EMU_BOOT_SCALE=0), 0.0, GROUND)
    ap.set_mode(0.0, GROUND, Mode.GUIDED_NOGPS)
    ap.arm(0.0, GROUND, True)
    ap.on_attitude_target(0.1, GROUND, angle(0.8))
    ap.tick(0.12, GROUND)
    assert isinstance(ap.demand, Idle)  # THEN thrust setpoints do not lift it
    assert math.isclose(ap.setpoint.setpoint.thrust_norm, 0.8)


def test_an_attitude_target_expires_at_its_deadline_between_ticks():
    ap = ArduCopter.start(1, params(), 0.0, AIR)
    ap.set_mode(0.0, AIR, Mode.GUIDED_NOGPS)
    sp = angle(0.4)
    ap.tick(10.0, AIR)
    ap.on_attitude_target(10.007, AIR, sp)
    assert ap.deadline_s == pytest.approx(13.007)
    ap.expire(13.007, AIR)  # not after the timeout yet (ArduCopter: strictly more than 3 s)
    assert ap.demand is sp.setpoint and ap.deadline_s == pytest.approx(13.007)
    ap.expire(13.0075, AIR)
    assert ap.demand is not sp.setpoint and ap.demand.thrust_norm == pytest.approx(0.35, abs=0.01)
    assert ap.deadline_s == math.inf and ap.guided_timeouts == 1


def test_repeating_a_climb_target_between_ticks_does_not_change_what_is_flown():
    # the altitude target integrates the climb rate over time (at the tick), not per setpoint
    def flown(setpoints_per_tick: int) -> float:
        ap = ArduCopter.start(1, params(), 0.0, AIR)
        ap.set_mode(0.0, AIR, Mode.GUIDED_NOGPS)
        for k in range(20):
            for j in range(setpoints_per_tick):
                ap.on_attitude_target(0.02 * k + 0.01 * j, AIR, angle(0.75, use_thrust=False))
            ap.tick(0.02 * k + 0.015, AIR)
        return ap.demand.thrust_norm

    once = flown(1)
    assert once > 0.35 and flown(2) == pytest.approx(once, rel=1e-12)
