"""Pure autopilot logic: PX4 offboard rules, loss actions, arming, takeoff/land, auto-disarm."""

from __future__ import annotations

import numpy as np
import pytest

from vehicle_emulator.autopilot import (
    Autopilot,
    Idle,
    MavResult,
    MotorsOff,
    NavState,
    Observation,
    PositionTarget,
    RatesSetpoint,
    Severity,
    custom_mode_of,
)
from vehicle_emulator.params import ParamStore

AIR = Observation((1.0, 2.0, 10.0), (0.0, 0.0, 0.0), 0.3, False)
GROUND = Observation((1.0, 2.0, 0.0), (0.0, 0.0, 0.0), 0.3, True)
SP = RatesSetpoint((0.0, 0.0, 0.0), 0.35)


def _stream(ap: Autopilot, t0: float, t1: float, hz: float = 50.0) -> None:
    for t in np.arange(t0, t1, 1.0 / hz):
        ap.on_setpoint(float(t), SP)


def test_custom_modes_are_px4s():
    assert custom_mode_of(NavState.OFFBOARD) == 393216
    assert custom_mode_of(NavState.AUTO_LAND) == (4 << 16) | (6 << 24)
    assert custom_mode_of(NavState.POSCTL) == 3 << 16


def test_a_vehicle_in_the_air_starts_armed_holding_its_position():
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    assert ap.armed and ap.nav_state is NavState.AUTO_LOITER
    assert ap.demand == PositionTarget(AIR.position_enu_m, yaw_enu_rad=0.3)
    assert not Autopilot.start(1, ParamStore(), 0.0, GROUND).armed


PX4_NO_OFFBOARD = "Switching to Offboard is currently not available"


def _armed_on_ground() -> Autopilot:
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    assert ap.arm(0.0, GROUND, True) is MavResult.ACCEPTED
    return ap


@pytest.mark.parametrize(
    "make, obs, armed",
    [
        (lambda: Autopilot.start(1, ParamStore(), 0.0, GROUND), GROUND, False),
        (_armed_on_ground, GROUND, True),
        (lambda: Autopilot.start(1, ParamStore(), 0.0, AIR), AIR, True),
    ],
    ids=["ground-disarmed", "ground-armed", "in-air"],
)
def test_one_setpoint_then_offboard_is_accepted_at_once(make, obs, armed):
    # GIVEN a vehicle that never saw a setpoint WHEN one arrives and DO_SET_MODE follows in the
    # same instant (MAVSDK's set_attitude_rate then start) THEN OFFBOARD is entered (PX4 SITL: 2-4 ms)
    ap = make()
    ap.on_setpoint(5.0, SP)
    assert ap.set_mode(5.0, obs, 6, 0) is MavResult.ACCEPTED
    assert ap.nav_state is NavState.OFFBOARD and ap.armed is armed
    assert ap.demand == (SP if armed else MotorsOff())
    assert ap.first_offboard_s == 5.0
    assert not any(PX4_NO_OFFBOARD in text for _, text in ap.events)


@pytest.mark.parametrize("now_s", [0.0, 3.0, 1000.0])
def test_offboard_without_any_setpoint_is_temporarily_rejected_with_px4s_text(now_s):
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    assert ap.set_mode(now_s, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED
    assert ap.nav_state is NavState.AUTO_LOITER and ap.first_offboard_s is None
    assert (Severity.CRITICAL, PX4_NO_OFFBOARD) in ap.events


@pytest.mark.parametrize(
    "age_s, accepted",
    [(0.0, True), (0.5, True), (0.99, True), (1.0, False), (1.01, False), (30.0, False)],
)
def test_offboard_needs_a_setpoint_younger_than_com_of_loss_t(age_s, accepted):
    # PX4: available iff now < last_setpoint + COM_OF_LOSS_T (default 1.0 s)
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    ap.on_setpoint(10.0, SP)
    result = ap.set_mode(10.0 + age_s, AIR, 6, 0)
    if accepted:
        assert result is MavResult.ACCEPTED and ap.nav_state is NavState.OFFBOARD
        assert ap.demand == SP
    else:
        assert result is MavResult.TEMPORARILY_REJECTED and ap.nav_state is NavState.AUTO_LOITER
        assert (Severity.CRITICAL, PX4_NO_OFFBOARD) in ap.events


def test_a_changed_com_of_loss_t_is_honoured():
    params = ParamStore({"COM_OF_LOSS_T": 2.5})
    ap = Autopilot.start(1, params, 0.0, AIR)
    ap.on_setpoint(1.0, SP)
    assert ap.set_mode(3.0, AIR, 6, 0) is MavResult.ACCEPTED  # 2.0 s old < 2.5 s
    short = Autopilot.start(1, ParamStore(), 0.0, AIR)
    short.on_setpoint(1.0, SP)
    short.params.set("COM_OF_LOSS_T", 0.3)  # changed at run time (PARAM_SET): read on each check
    assert short.set_mode(1.5, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED  # 0.5 s old > 0.3 s
    assert short.set_mode(1.25, AIR, 6, 0) is MavResult.ACCEPTED


def test_setpoint_rate_does_not_matter_only_recency():
    # no ">= 2 Hz for > 1 s" rule: a 1.5 Hz trickle qualifies whenever its newest setpoint is young
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    _stream(ap, 0.0, 5.0, hz=1.5)  # the newest setpoint is at 4.67 s
    assert ap.set_mode(5.0, AIR, 6, 0) is MavResult.ACCEPTED


@pytest.mark.parametrize(
    "action, state", [(0, NavState.POSCTL), (5, NavState.AUTO_LOITER), (4, NavState.AUTO_LAND)]
)
def test_setpoint_loss_after_com_of_loss_t_runs_the_action(action, state):
    params = ParamStore({"COM_OBL_RC_ACT": action, "COM_OF_LOSS_T": 0.5})
    ap = Autopilot.start(1, params, 0.0, AIR)
    _stream(ap, 0.0, 1.2)
    ap.set_mode(1.2, AIR, 6, 0)
    last = 1.2 - 0.02
    ap.tick(last + 0.49, AIR)
    assert ap.nav_state is NavState.OFFBOARD
    ap.tick(last + 0.51, AIR)
    assert ap.nav_state is state and ap.armed
    assert isinstance(ap.demand, PositionTarget)
    if state is NavState.AUTO_LAND:
        assert ap.demand.mask[2] == 0.0 and ap.demand.velocity_ff_enu_mps[2] < 0
    else:
        assert ap.demand.position_enu_m == AIR.position_enu_m  # holds where it was
    assert any("offboard setpoints lost" in text for _, text in ap.events)


def test_arming_rules():
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    assert ap.arm(0.0, GROUND, True) is MavResult.ACCEPTED and ap.demand == Idle()
    assert ap.arm(1.0, GROUND, False) is MavResult.ACCEPTED and ap.demand == MotorsOff()
    flying = Autopilot.start(1, ParamStore(), 0.0, AIR)
    assert flying.arm(0.0, AIR, False) is MavResult.DENIED  # in the air
    assert flying.arm(0.0, AIR, False, force=True) is MavResult.ACCEPTED
    low = Observation(GROUND.position_enu_m, (0, 0, 0), 0.0, True, battery_remaining=0.05)
    assert Autopilot.start(1, ParamStore(), 0.0, GROUND).arm(0, low, True) is MavResult.DENIED
    ap2 = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    ap2.nav_state = NavState.OFFBOARD
    assert ap2.arm(0.0, GROUND, True) is MavResult.DENIED  # offboard without any setpoint
    ap2.on_setpoint(1.0, SP)
    assert ap2.arm(2.0, GROUND, True) is MavResult.DENIED  # newest setpoint 1.0 s old
    assert ap2.arm(2.5, GROUND, True) is MavResult.DENIED
    ap2.on_setpoint(3.0, SP)
    assert ap2.arm(3.0, GROUND, True) is MavResult.ACCEPTED  # one fresh setpoint is enough
    assert ap2.demand == SP


def test_takeoff_hold_land_and_auto_disarm():
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    ap.arm(0.0, GROUND, True)
    assert ap.takeoff(0.1, GROUND, 3.0) is MavResult.ACCEPTED
    assert isinstance(ap.demand, PositionTarget) and ap.demand.velocity_ff_enu_mps[2] == 1.5
    mid = Observation((1.0, 2.0, 2.0), (0, 0, 1.0), 0.3, False)
    ap.tick(2.0, mid)  # within MPC_TKO_SPEED of the target: capture the altitude
    assert ap.demand.mask == (1.0, 1.0, 1.0) and ap.demand.position_enu_m[2] == 3.0
    top = Observation((1.0, 2.0, 2.9), (0, 0, 0), 0.3, False)
    ap.tick(3.0, top)
    assert ap.nav_state is NavState.AUTO_LOITER
    assert ap.land(4.0, top) is MavResult.ACCEPTED and ap.nav_state is NavState.AUTO_LAND
    ap.tick(8.0, GROUND)
    assert ap.armed and ap.demand == Idle()
    ap.tick(10.1, GROUND)  # COM_DISARM_LAND = 2 s
    assert not ap.armed and ap.demand == MotorsOff()


def test_preflight_disarm_when_no_takeoff():
    ap = Autopilot.start(1, ParamStore({"COM_DISARM_PRFLT": 3.0}), 0.0, GROUND)
    ap.arm(0.0, GROUND, True)
    ap.tick(2.9, GROUND)
    assert ap.armed
    ap.tick(3.1, GROUND)
    assert not ap.armed


def test_modes_without_rc_are_refused():
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    for main in (1, 5, 7):
        assert ap.set_mode(0.0, AIR, main, 0) is MavResult.DENIED
    assert ap.set_mode(0.0, AIR, 4, 4) is MavResult.DENIED  # AUTO.MISSION: no mission
