"""Preflight after a landing (gcs.mission.landed and the mission machine, pure): a PX4 vehicle
disarmed in OFFBOARD sends no ATTITUDE_TARGET (PX4 v1.16.0 SIH, 2026-12-04; docs/emulator.md,
"After a landing"), so preflight leaves that mode before it judges the streams, and says so
when a stream still does not come."""

from __future__ import annotations

import dataclasses

from test_mission import RULES, World, status

from gcs.mission.autopilots import ARDUPILOT, PX4
from gcs.mission.landed import quiet_mode_cause, with_quiet_causes
from gcs.mission.machine import EXIT_ABORTED, EXIT_OK, Cmd, MissionMachine, MissionPlan
from gcs.mission.safety import preflight_problems

HOVER_RULES = dataclasses.replace(
    RULES, required_rates_hz={**RULES.required_rates_hz, "ATTITUDE_TARGET": 10.0})
FULL = {"ATTITUDE_QUATERNION": 99.0, "LOCAL_POSITION_NED": 98.0, "ATTITUDE_TARGET": 10.0}
QUIET_LINE = "vehicle 1 (sysid 1): disarmed in OFFBOARD: PX4 sends no ATTITUDE_TARGET there"


class Px4AfterLanding(World):
    """One PX4 vehicle on the ground that sends ATTITUDE_TARGET except while disarmed in
    OFFBOARD (as PX4 v1.16.0 does), starting there."""

    def __init__(self, machine: MissionMachine) -> None:
        super().__init__(machine, on_ground=True)
        self.v[1] = dataclasses.replace(self.v[1], mode="OFFBOARD")

    def tick(self, dt: float = 0.05) -> None:
        self.t += dt
        for vid, s in self.v.items():
            quiet = not s.armed and s.mode == "OFFBOARD"
            self.v[vid] = dataclasses.replace(
                s, rates_hz={**FULL, "ATTITUDE_TARGET": 0.0 if quiet else 10.0})
        self.apply(self.m.on_tick(self.t, list(self.v.values())))
        # (World's invariant, for an armed vehicle: disarmed in OFFBOARD is where this starts)
        for vid, s in self.v.items():
            if s.armed and s.mode == "OFFBOARD" and not self.m.done:
                assert vid in self.m.streaming, f"vehicle {vid} in OFFBOARD without setpoints"


def one_vehicle(**plan) -> MissionMachine:
    return MissionMachine(MissionPlan(duration_s=plan.pop("duration_s", 5.0), rules=HOVER_RULES,
                                      arm_timeout_s=20.0, **plan), (1,))


def landed_in_offboard(**kw):
    base = dict(armed=False, landed=True, landed_state=1, mode="OFFBOARD",
                position_enu_m=(3.0, 0.0, 0.0))
    return status(1, **{**base, **kw})


def test_a_px4_vehicle_disarmed_in_offboard_is_put_in_hold_before_its_streams_are_judged():
    # GIVEN PX4 landed from OFFBOARD, disarmed there: no ATTITUDE_TARGET, which from_hover needs
    m = one_vehicle()
    w = Px4AfterLanding(m)
    # WHEN the flight runs
    w.run(40.0)
    # THEN preflight commands Hold first, with the cause in a note; the stream comes back, the
    # checks pass, the vehicle arms, takes off and flies: exit 0
    cmds = [c for _, c in w.sent]
    assert cmds[:4] == [Cmd.CONFIGURE, Cmd.ARM_MODE, Cmd.ARM, Cmd.TAKEOFF], cmds
    assert cmds.count(Cmd.ARM_MODE) == 1
    assert f"{QUIET_LINE}: commanding AUTO_LOITER first" in m.notes
    assert m.outcome is not None and m.outcome.exit_code == EXIT_OK, m.outcome


def test_a_refused_hold_names_the_mode_the_vehicle_is_stuck_in():
    # GIVEN the same vehicle WHEN it refuses Hold THEN the flight stops, naming why Hold was asked
    m = one_vehicle()
    w = Px4AfterLanding(m)
    w.reject.add((1, Cmd.ARM_MODE))
    w.run(10.0)
    assert m.outcome is not None and m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason.startswith(f"{QUIET_LINE}; vehicle 1: arm_mode failed: no"), \
        m.outcome.reason


def test_a_missing_attitude_target_is_reported_with_its_cause():
    # GIVEN PX4 disarmed in OFFBOARD, ATTITUDE_TARGET required at 10 Hz and none arriving
    s = landed_in_offboard(rates_hz={**FULL, "ATTITUDE_TARGET": 0.0})
    # WHEN the preflight problems are explained
    problems = with_quiet_causes(preflight_problems([s], HOVER_RULES), [s], {1: PX4})
    # THEN the line names the mode and the autopilot's behaviour first, then what was measured
    assert [p.text for p in problems] == [
        f"{QUIET_LINE} (ATTITUDE_TARGET at 0.0 Hz, need >= 5 Hz (asked 10))"]
    assert problems[0].kind == "ready"


def test_only_a_disarmed_px4_vehicle_in_offboard_on_the_ground_is_quiet():
    assert quiet_mode_cause(PX4, landed_in_offboard()) == QUIET_LINE
    assert quiet_mode_cause(PX4, landed_in_offboard(armed=True)) is None
    assert quiet_mode_cause(PX4, landed_in_offboard(mode="AUTO_LOITER")) is None
    assert quiet_mode_cause(PX4, landed_in_offboard(landed=False)) is None
    # ArduPilot sends ATTITUDE_TARGET in every mode
    assert quiet_mode_cause(ARDUPILOT, landed_in_offboard(mode="GUIDED_NOGPS")) is None
    # AND a shortfall in another mode keeps its own text
    s = landed_in_offboard(mode="AUTO_LOITER", rates_hz={**FULL, "ATTITUDE_TARGET": 2.0})
    problems = with_quiet_causes(preflight_problems([s], HOVER_RULES), [s], {1: PX4})
    assert [p.text for p in problems] == [
        "vehicle 1 (sysid 1): ATTITUDE_TARGET at 2.0 Hz, need >= 5 Hz (asked 10)"]
