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


def test_offboard_needs_more_than_one_second_of_stream():
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    assert ap.set_mode(0.0, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED
    _stream(ap, 0.0, 0.99)
    assert ap.set_mode(0.99, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED
    _stream(ap, 0.99, 1.1)
    assert ap.set_mode(1.1, AIR, 6, 0) is MavResult.ACCEPTED
    assert ap.nav_state is NavState.OFFBOARD and ap.demand == SP
    assert ap.first_offboard_s == 1.1


def test_a_stream_slower_than_2_hz_never_qualifies():
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    _stream(ap, 0.0, 5.0, hz=1.5)
    assert ap.set_mode(5.0, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED


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
    assert ap2.arm(0.0, GROUND, True) is MavResult.DENIED  # offboard without a stream


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
