"""Pure autopilot logic: PX4 offboard rules, loss actions, arming, takeoff/land, auto-disarm,
intended mode (PX4 v1.16.0 as recorded in ../shared/data/sitl/px4/modes_and_acks)."""

from __future__ import annotations

import numpy as np
import pytest

from vehicle_emulator.autopilots.px4.logic import (
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
from vehicle_emulator.config.params import ParamStore

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
PX4_ARMING_DENIED = "Arming denied: Resolve system health failures first"
PX4_FAILSAFE = "Failsafe activated"


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
def test_armed_offboard_without_any_setpoint_is_temporarily_rejected_with_px4s_text(now_s):
    ap = Autopilot.start(1, ParamStore(), 0.0, AIR)
    assert ap.set_mode(now_s, AIR, 6, 0) is MavResult.TEMPORARILY_REJECTED
    assert ap.nav_state is NavState.AUTO_LOITER and ap.first_offboard_s is None
    assert ap.intended_state is NavState.AUTO_LOITER
    assert (Severity.CRITICAL, PX4_NO_OFFBOARD) in ap.events


@pytest.mark.parametrize(
    "main, sub, state",
    [
        (6, 0, NavState.OFFBOARD),
        (3, 0, NavState.POSCTL),
        (2, 0, NavState.ALTCTL),
        (4, 3, NavState.AUTO_LOITER),
        (4, 6, NavState.AUTO_LAND),
        (4, 2, NavState.AUTO_TAKEOFF),
    ],
)
def test_disarmed_every_available_mode_is_accepted_offboard_without_a_setpoint_too(
    main, sub, state
):
    # GIVEN a disarmed vehicle that never saw a setpoint (PX4 v1.16.0, 6.44 s: ACCEPTED)
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    ap.set_mode(0.0, GROUND, 3, 0)  # start from another mode than the target
    # WHEN a mode is selected THEN it is accepted, current and intended, motors off
    assert ap.set_mode(5.0, GROUND, main, sub) is MavResult.ACCEPTED
    assert ap.nav_state is state and ap.intended_state is state
    assert not ap.armed and ap.demand == MotorsOff()
    assert not any(sev is Severity.CRITICAL for sev, _ in ap.events)


def test_disarmed_offboard_without_setpoints_has_no_failsafe_and_refuses_to_arm():
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    assert ap.set_mode(1.0, GROUND, 6, 0) is MavResult.ACCEPTED
    # GIVEN disarmed in OFFBOARD, no setpoint WHEN time passes THEN it stays in OFFBOARD (PX4
    # v1.16.0's HEARTBEAT showed OFFBOARD until the next mode command, 4 s later)
    for t in np.arange(1.0, 10.0, 0.02):
        ap.tick(float(t), GROUND)
    assert ap.nav_state is NavState.OFFBOARD and not ap.armed
    ap.events.clear()
    # WHEN armed THEN TEMPORARILY_REJECTED with PX4's text, severity CRITICAL
    assert ap.arm(10.0, GROUND, True) is MavResult.TEMPORARILY_REJECTED
    assert ap.events == [(Severity.CRITICAL, PX4_ARMING_DENIED)] and not ap.armed
    # a setpoint older than COM_OF_LOSS_T does not help; a fresh one does
    ap.on_setpoint(10.0, SP)
    assert ap.arm(11.0, GROUND, True) is MavResult.TEMPORARILY_REJECTED
    ap.on_setpoint(12.0, SP)
    assert ap.arm(12.5, GROUND, True) is MavResult.ACCEPTED and ap.demand == SP


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
    assert (Severity.CRITICAL, PX4_FAILSAFE) in ap.events  # PX4's text
    assert ap.intended_state is NavState.OFFBOARD  # a failsafe is not a user's choice
    assert ap.failsafe_active and ap.system_status(last + 0.51) == 5


@pytest.mark.parametrize("state", [NavState.POSCTL, NavState.ALTCTL])
def test_without_manual_control_position_and_altitude_descend_at_full_stick(state):
    # PX4 v1.16.0 with COM_RC_IN_MODE 4 (the px4 personality's default): the Position failsafe
    # descended at 1.04 m/s, i.e. MPC_Z_VEL_MAX_DN with the throttle stick read as full down
    params = ParamStore({"COM_RC_IN_MODE": 4, "COM_OBL_RC_ACT": 0 if state is NavState.POSCTL
                         else 1})
    ap = _offboard_in_the_air(params)
    ap.tick(2.3, AIR)
    assert ap.nav_state is state
    assert isinstance(ap.demand, PositionTarget)
    assert ap.demand.mask[2] == 0.0 and ap.demand.velocity_ff_enu_mps[2] == -1.0
    # a commanded Position is flown the same way, and it ends in a landing
    assert ap.set_mode(3.0, AIR, 3, 0) is MavResult.ACCEPTED
    assert ap.demand.velocity_ff_enu_mps[2] == -1.0 and not ap.failsafe_active
    _land_and_wait(ap, 10.0, 12.2)
    assert not ap.armed


def _offboard_in_the_air(params: ParamStore) -> Autopilot:
    """Armed at 10 m, streamed setpoints until 1.18 s, OFFBOARD since 1.2 s."""
    ap = Autopilot.start(1, params, 0.0, AIR)
    _stream(ap, 0.0, 1.2)
    assert ap.set_mode(1.2, AIR, 6, 0) is MavResult.ACCEPTED
    return ap


def _land_and_wait(ap: Autopilot, t0: float, t1: float) -> None:
    """Ground contact from t0 on, ticks at 50 Hz until t1."""
    for t in np.arange(t0, t1, 0.02):
        ap.tick(float(t), GROUND)


def test_after_a_failsafe_landing_the_vehicle_returns_to_the_intended_offboard():
    # GIVEN OFFBOARD in the air and a loss action that lands (COM_OBL_RC_ACT 4)
    ap = _offboard_in_the_air(ParamStore({"COM_OBL_RC_ACT": 4}))
    # WHEN the setpoints stop THEN the failsafe lands it; OFFBOARD stays the intended mode
    ap.tick(2.3, AIR)
    assert ap.nav_state is NavState.AUTO_LAND and ap.intended_state is NavState.OFFBOARD
    # WHEN it touches down THEN "Landing detected", and COM_DISARM_LAND (2 s) later "Disarmed by
    # landing" and the mode is OFFBOARD again, disarmed (PX4 v1.16.0: HEARTBEAT 393216, base 1)
    ap.events.clear()
    _land_and_wait(ap, 10.0, 11.9)
    assert ap.armed and ap.nav_state is NavState.AUTO_LAND
    assert ap.events == [(Severity.INFO, "Landing detected")]
    _land_and_wait(ap, 11.9, 12.2)
    assert not ap.armed and ap.nav_state is NavState.OFFBOARD
    assert ap.demand == MotorsOff()
    assert (Severity.INFO, "Disarmed by landing") in ap.events
    # AND arming there is refused (no setpoint younger than COM_OF_LOSS_T)
    assert ap.arm(15.0, GROUND, True) is MavResult.TEMPORARILY_REJECTED
    assert ap.events[-1] == (Severity.CRITICAL, PX4_ARMING_DENIED)
    # AND a user mode selection ends it (PX4 v1.16.0: AUTO_LOITER then arming ACCEPTED)
    assert ap.set_mode(16.0, GROUND, 4, 3) is MavResult.ACCEPTED
    assert ap.arm(17.0, GROUND, True) is MavResult.ACCEPTED


def test_a_gcs_commanded_land_from_offboard_ends_disarmed_in_offboard():
    # GIVEN OFFBOARD in the air WHEN the GCS sends NAV_LAND THEN Land is the intended mode, but
    # not the mode after disarming (Land prevents arming: PX4's UserModeIntention)
    ap = _offboard_in_the_air(ParamStore())
    assert ap.land(1.2, AIR) is MavResult.ACCEPTED
    assert ap.nav_state is ap.intended_state is NavState.AUTO_LAND
    assert ap.after_disarm_state is NavState.OFFBOARD
    assert ap.attitude_target_published()
    # WHEN it lands and auto-disarms THEN it is disarmed in OFFBOARD, as PX4 v1.16.0 SIH was
    # after every rates flight of 2026-12-04 (HEARTBEAT base_mode 1, custom_mode 393216), with
    # its pre-arm check failing and no ATTITUDE_TARGET
    _land_and_wait(ap, 10.0, 12.2)
    assert not ap.armed and ap.nav_state is ap.intended_state is NavState.OFFBOARD
    assert (Severity.INFO, "Disarmed by landing") in ap.events
    assert not ap.prearm_ok(13.0) and not ap.attitude_target_published()
    # AND Hold, accepted disarmed, ends it: pre-arm passes, setpoints are published again
    assert ap.set_mode(14.0, GROUND, 4, 3) is MavResult.ACCEPTED
    assert ap.prearm_ok(14.0) and ap.attitude_target_published()


def test_a_failsafe_that_holds_then_a_gcs_land_ends_in_offboard():
    # GIVEN the default loss action (Position) WHEN the GCS then lands it THEN after the landing
    # it is back in OFFBOARD, the last selected mode that allows arming
    ap = _offboard_in_the_air(ParamStore())
    ap.tick(2.3, AIR)
    assert ap.nav_state is NavState.POSCTL and ap.intended_state is NavState.OFFBOARD
    assert ap.land(3.0, AIR) is MavResult.ACCEPTED and ap.intended_state is NavState.AUTO_LAND
    _land_and_wait(ap, 10.0, 12.2)
    assert not ap.armed and ap.nav_state is NavState.OFFBOARD


def test_after_a_landing_from_hold_the_vehicle_stays_in_hold():
    # GIVEN Hold selected in the air (the GCS's hold before a land) WHEN it lands THEN Hold,
    # the mode after disarming, is its mode again
    ap = _offboard_in_the_air(ParamStore())
    assert ap.set_mode(2.0, AIR, 4, 3) is MavResult.ACCEPTED
    assert ap.land(3.0, AIR) is MavResult.ACCEPTED
    _land_and_wait(ap, 10.0, 12.2)
    assert not ap.armed and ap.nav_state is NavState.AUTO_LOITER
    assert ap.prearm_ok(13.0) and ap.attitude_target_published()


def test_intended_mode_follows_commands_and_the_takeoff_completion():
    ap = Autopilot.start(1, ParamStore(), 0.0, GROUND)
    assert ap.intended_state is NavState.AUTO_LOITER  # the boot mode
    ap.arm(0.0, GROUND, True)
    ap.takeoff(0.1, GROUND, 3.0)
    assert ap.intended_state is NavState.AUTO_TAKEOFF
    ap.tick(2.0, Observation((1.0, 2.0, 2.0), (0, 0, 1.0), 0.3, False))
    ap.tick(3.0, Observation((1.0, 2.0, 2.9), (0, 0, 0), 0.3, False))
    # PX4's navigator selects Hold after the takeoff: CURRENT_MODE's intended mode follows
    assert ap.nav_state is ap.intended_state is NavState.AUTO_LOITER
    assert ap.set_mode(4.0, AIR, 3, 0) is MavResult.ACCEPTED
    assert ap.intended_state is NavState.POSCTL
    assert ap.set_mode(4.1, AIR, 1, 0) is MavResult.DENIED  # refused: intended unchanged
    assert ap.intended_state is NavState.POSCTL


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
    assert ap2.set_mode(0.0, GROUND, 6, 0) is MavResult.ACCEPTED  # disarmed: any mode
    # offboard without any setpoint: PX4 v1.16.0 answered TEMPORARILY_REJECTED
    assert ap2.arm(0.0, GROUND, True) is MavResult.TEMPORARILY_REJECTED
    ap2.on_setpoint(1.0, SP)
    assert ap2.arm(2.0, GROUND, True) is MavResult.TEMPORARILY_REJECTED  # 1.0 s old
    assert ap2.arm(2.5, GROUND, True) is MavResult.TEMPORARILY_REJECTED
    assert ap2.arm(2.5, GROUND, True, force=True) is MavResult.ACCEPTED  # 21196 skips checks
    assert ap2.arm(2.6, GROUND, False) is MavResult.ACCEPTED
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
