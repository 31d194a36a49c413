"""Autopilot profiles (PX4, ArduPilot Copter) and the mission machine driving ArduPilot and mixed
teams (pure: no sockets, no clock; time and telemetry are arguments)."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.link.enums import ArduCopterMode, mode_name, px4_custom_mode
from gcs.mission.autopilots import (
    ARDUPILOT,
    GUID_OPTIONS_THRUST,
    PX4,
    AutopilotProfile,
    profile_for,
    unsupported_text,
)
from gcs.mission.machine import (
    EXIT_ABORTED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    Cmd,
    Command,
    CommandResult,
    MissionMachine,
    MissionPlan,
    Phase,
)
from gcs.mission.safety import SafetyRules, VehicleStatus, preflight_problems

RATES = {"ATTITUDE_QUATERNION": 100.0, "LOCAL_POSITION_NED": 100.0}
RULES = SafetyRules(max_tilt_rad=1.0, link_lost_after_s=0.5, geofence_min_enu_m=(-50, -50, 1),
                    geofence_max_enu_m=(50, 50, 50), required_rates_hz=RATES)
FIX = "set GUID_OPTIONS bit 3 (8): otherwise ArduPilot reads thrust as a climb rate"


# --- the profiles --------------------------------------------------------------------------------


def test_profiles_are_chosen_from_heartbeat_autopilot():
    assert profile_for(12) is PX4 and profile_for(3) is ARDUPILOT
    assert profile_for(0) is None and profile_for(8) is None
    assert unsupported_text("vehicle 1 (sysid 1)", 0) == (
        "vehicle 1 (sysid 1): autopilot 0 is not supported; gcs fly flies PX4 (12) and "
        "ArduPilot Copter (3) only")


def test_ardupilot_profile_holds_the_spec_facts():
    a = ARDUPILOT
    assert (a.offboard.name, a.offboard.number) == ("GUIDED_NOGPS", 20)
    assert (a.hold.name, a.hold.number) == ("BRAKE", 17)
    assert a.land is not None and (a.land.name, a.land.number) == ("LAND", 9)
    assert (a.arm_mode.name, a.arm_mode.number) == ("GUIDED", 4)
    assert not a.prearm_bit_reliable
    assert a.arm_retryable("FAILED", "Arm: Need Position Estimate")
    assert a.arm_retryable("FAILED", "PreArm: Gyros inconsistent")
    assert not a.arm_retryable("FAILED", "Throttle too high") and not a.arm_retryable("DENIED", "")
    assert not a.takeoff_altitude_amsl and a.takeoff_done_modes == {"GUIDED"}
    assert a.setpoint_modes == {"GUIDED", "GUIDED_NOGPS"} and a.hold_before_prime
    assert (a.force_arm_magic, a.force_disarm_magic) == (2989, 21196)
    assert a.control_modes == {"rates", "attitude", "position"}
    assert a.required_params == (GUID_OPTIONS_THRUST,) and GUID_OPTIONS_THRUST.mask == 8
    # the formation's setpoints: SET_ATTITUDE_TARGET in GUIDED_NOGPS; position mode's
    # SET_POSITION_TARGET_LOCAL_NED in GUIDED (GUIDED_NOGPS takes no position target)
    assert a.flies_in("rates") == a.flies_in("attitude") == a.offboard
    assert (a.flies_in("position").name, a.flies_in("position").number) == ("GUIDED", 4)
    # GUID_OPTIONS bit 3 says how thrust is read: position mode sends none
    assert a.params_for("rates") == (GUID_OPTIONS_THRUST,) and a.params_for("position") == ()


def test_px4_profile_is_what_gcs_fly_did_before():
    p = PX4
    assert p.offboard.custom_mode("px4") == 393216 == px4_custom_mode(6)
    assert p.hold.custom_mode("px4") == px4_custom_mode(4, 3) and p.hold.name == "AUTO_LOITER"
    assert p.land is None and p.takeoff_altitude_amsl
    assert p.arm_mode == p.hold and p.prearm_bit_reliable
    assert p.arm_retryable("TEMPORARILY_REJECTED", "") and p.arm_retryable("NOT_CONFIRMED", "")
    assert not p.arm_retryable("DENIED", "Arming denied: not landed")
    assert not p.arm_retryable("FAILED", "Arm: x") and not p.arm_retryable("TIMEOUT", "")
    assert not p.hold_before_prime and not p.required_params
    assert p.control_modes == {"rates", "actuators", "attitude", "position"}
    assert p.flies_in("position") == p.flies_in("rates") == p.offboard  # OFFBOARD either way
    assert (p.force_arm_magic, p.force_disarm_magic) == (21196, 21196)


@pytest.mark.parametrize("profile", [PX4, ARDUPILOT], ids=lambda p: p.name)
def test_mode_names_agree_with_the_link_layer_and_the_mode_specs(profile: AutopilotProfile):
    # GIVEN every custom_mode the link layer can name for this autopilot
    if profile.family == "px4":
        modes = [px4_custom_mode(main, sub) for main in range(9) for sub in range(8)]
    else:
        modes = [int(m) for m in ArduCopterMode] + [8, 99]
    # THEN the profile names them as gcs.link.enums.mode_name does (BRAKE etc. beyond it)
    for cm in modes:
        assert profile.mode_name(cm) == mode_name(profile.autopilot, cm), cm
    # AND every mode the profile commands reads back under its own name
    specs = [profile.offboard, profile.hold, profile.land, profile.arm_mode]
    for spec in (s for s in specs if s is not None):
        assert profile.mode_name(spec.custom_mode(profile.family)) == spec.name
    assert ARDUPILOT.mode_name(17) == "BRAKE"


@pytest.mark.parametrize("value,ok", [(8.0, True), (72.0, True), (15.0, True), (0.0, False),
                                      (7.0, False), (64.0, False), (None, False),
                                      (math.nan, False)])
def test_guid_options_bit_3_is_required(value, ok):
    text = GUID_OPTIONS_THRUST.problem("vehicle 2 (sysid 5)", value)
    assert (text is None) == ok
    if not ok:
        assert text.startswith("vehicle 2 (sysid 5): GUID_OPTIONS ") and text.endswith(FIX)
        assert "\n" not in text
    if value == 0.0:
        assert text == f"vehicle 2 (sysid 5): GUID_OPTIONS = 0 (bit mask 8 clear); {FIX}"


def test_ardupilot_refuses_actuator_setpoints():
    assert ARDUPILOT.preflight_problems("vehicle 1 (sysid 1)", "actuators", {"GUID_OPTIONS": 8}) \
        == ["vehicle 1 (sysid 1): ArduPilot Copter does not act on actuators setpoints; fly it "
            "with --mode attitude or rates"]
    assert ARDUPILOT.preflight_problems("v", "rates", {"GUID_OPTIONS": 8}) == []


def _version(major: int, minor: int, patch: int) -> int:
    return (major << 24) | (minor << 16) | (patch << 8) | 255


def test_px4_actuators_only_where_its_autopilot_version_acts_on_them():
    # PX4 1.14 dropped SET_ACTUATOR_CONTROL_TARGET: 1.16.0 ignores it without any refusal
    assert PX4.needs_version("actuators") and not PX4.needs_version("rates")
    assert PX4.preflight_problems("v", "actuators", None, _version(1, 13, 3)) == []
    assert PX4.preflight_problems("vehicle 2 (sysid 2)", "actuators", None,
                                  _version(1, 16, 0)) == [
        "vehicle 2 (sysid 2): PX4 1.16.0 ignores SET_ACTUATOR_CONTROL_TARGET (only <= 1.13 acts "
        "on it); fly it with --mode rates"]
    assert PX4.preflight_problems("v", "actuators", None, _version(2, 0, 0)) != []
    # no answer: not confirmed, refused
    assert PX4.preflight_problems("vehicle 1 (sysid 1)", "actuators", None, None) == [
        "vehicle 1 (sysid 1): no AUTOPILOT_VERSION: cannot confirm that PX4 acts on actuator "
        "setpoints (only <= 1.13 does); fly it with --mode rates"]
    assert PX4.preflight_problems("v", "rates", None, None) == []


def test_preflight_accepts_ardupilot_and_refuses_unknown_autopilots():
    team = [status(1, 3), status(2, 12), status(3, 4)]
    texts = [p.text for p in preflight_problems(team, RULES)]
    assert texts == [unsupported_text("vehicle 3 (sysid 3)", 4)]


# --- the machine with ArduPilot (and mixed) statuses ---------------------------------------------

ARDU_SETPOINT_MODES = ARDUPILOT.setpoint_modes


def status(vid: int, autopilot: int, **kw) -> VehicleStatus:
    base = dict(vehicle_id=vid, sysid=vid, link="alive", armed=True,
                mode="BRAKE" if autopilot == 3 else "AUTO_LOITER", landed=False,
                position_enu_m=(vid * 3.0, 0.0, 10.0), velocity_enu_mps=(0, 0, 0), tilt_rad=0.01,
                data_age_s=0.01, autopilot=autopilot, vehicle_type=2, landed_state=2,
                rates_hz={"ATTITUDE_QUATERNION": 99.0, "LOCAL_POSITION_NED": 98.0})
    base.update(kw)
    return VehicleStatus(**base)


class World:
    """A fake team that obeys like its autopilots would (ArduPilot: arming enters GUIDED,
    NAV_TAKEOFF only in GUIDED, and the vehicle stays in GUIDED afterwards; setpoints act only in
    GUIDED/GUIDED_NOGPS), and checks the safety invariants after every tick."""

    def __init__(self, machine: MissionMachine, autopilots: dict[int, int], *,
                 on_ground: bool = False, guid_options: float = 8.0,
                 in_air_mode: str | None = None) -> None:
        self.m = machine
        self.t = 0.0
        self.v = {}
        for vid, ap in autopilots.items():
            s = status(vid, ap, armed=not on_ground, landed=on_ground,
                       landed_state=1 if on_ground else 2,
                       position_enu_m=(vid * 3.0, 0.0, 0.0 if on_ground else 10.0))
            if on_ground:
                s = dataclasses.replace(s, mode="STABILIZE" if ap == 3 else "AUTO_READY")
            elif in_air_mode is not None and ap == 3:
                s = dataclasses.replace(s, mode=in_air_mode)
            self.v[vid] = s
        self.params = {vid: {"GUID_OPTIONS": guid_options} for vid in autopilots}
        self.versions = {vid: _version(1, 13, 3) for vid in autopilots}
        self.sent: list[Command] = []
        self.reject: set[tuple[int, Cmd]] = set()
        self.ignore: set[tuple[int, Cmd]] = set()  # acknowledged, without effect
        self.silent: set[int] = set()
        self.acted_before_formation: list[int] = []
        self.modes: dict[int, list[str]] = {}  # per vehicle, each mode a command put it in

    def cmds(self, vid: int | None = None) -> list[Cmd]:
        return [c.cmd for c in self.sent if vid is None or c.vehicle_id == vid]

    def _obey(self, c: Command, s: VehicleStatus) -> tuple[VehicleStatus, bool, tuple]:
        ardu = s.autopilot == 3
        if (c.vehicle_id, c.cmd) in self.reject:
            return s, False, ()
        if (c.vehicle_id, c.cmd) in self.ignore:
            return s, True, ()
        if c.cmd is Cmd.READ_PARAMS:
            return s, True, tuple((n, self.params[c.vehicle_id][n]) for n in c.names)
        if c.cmd is Cmd.IDENTIFY:
            return s, True, (("flight_sw_version", float(self.versions[c.vehicle_id])),)
        if c.cmd is Cmd.ARM_MODE:
            return dataclasses.replace(s, mode="GUIDED" if ardu else "AUTO_LOITER"), True, ()
        if c.cmd is Cmd.ARM:
            return dataclasses.replace(s, armed=True), True, ()
        if c.cmd is Cmd.TAKEOFF:
            if ardu and not (s.armed and s.mode == "GUIDED"):
                return s, False, ()
            return dataclasses.replace(s, landed=False, mode="GUIDED" if ardu else "AUTO_LOITER",
                                       landed_state=2,
                                       position_enu_m=(s.position_enu_m[0], 0.0, c.altitude_m)
                                       ), True, ()
        if c.cmd is Cmd.OFFBOARD:  # the mode the app commands for it (Commander.execute)
            return dataclasses.replace(s, mode=self.m.offboard_mode(c.vehicle_id).name), True, ()
        if c.cmd is Cmd.HOLD:
            return dataclasses.replace(s, mode="BRAKE" if ardu else "AUTO_LOITER"), True, ()
        if c.cmd is Cmd.LAND:
            return dataclasses.replace(s, mode="LAND" if ardu else "AUTO_LAND", landed=True,
                                       armed=False, landed_state=1,
                                       position_enu_m=(s.position_enu_m[0], 0.0, 0.0)), True, ()
        if c.cmd is Cmd.DISARM:
            return dataclasses.replace(s, armed=False), True, ()
        return s, True, ()

    def apply(self, cmds) -> None:
        for c in cmds:
            self.sent.append(c)
            s, ok, values = self._obey(c, self.v[c.vehicle_id])
            if s.mode != self.v[c.vehicle_id].mode:
                self.modes.setdefault(c.vehicle_id, []).append(s.mode)
            self.v[c.vehicle_id] = s
            result = CommandResult(c.vehicle_id, c.cmd, ok, "" if ok else "no", values)
            self.apply(self.m.on_result(result))

    def tick(self, dt: float = 0.05) -> None:
        self.t += dt
        team = [dataclasses.replace(s, link="lost", data_age_s=9.0) if vid in self.silent else s
                for vid, s in self.v.items()]
        self.apply(self.m.on_tick(self.t, team))
        for vid, s in self.v.items():
            # THE invariant: a vehicle the GCS put in its offboard mode (position mode:
            # ArduPilot GUIDED, where its takeoff also leaves it) with its link up gets setpoints
            offboard = self.m.offboard_mode(vid).name
            commanded = {Cmd.OFFBOARD, Cmd.POSITION_MODE} & set(self.cmds(vid))
            # (law setpoints, or the go-to-start's position setpoints; never both at once)
            assert not self.m.streaming & set(self.m.position_targets)
            if s.mode == offboard and commanded and vid not in self.silent and not self.m.done:
                assert vid in self.m.streaming or vid in self.m.position_targets, \
                    f"vehicle {vid} in {offboard} without setpoints"
            # and priming is inert: before the formation no streamed setpoint is acted on
            if (self.m.formation_t0_s is None and vid in self.m.streaming
                    and s.autopilot == 3 and s.mode in ARDU_SETPOINT_MODES):
                self.acted_before_formation.append(vid)

    def run(self, seconds: float) -> None:
        for _ in range(int(seconds / 0.05)):
            if self.m.done:
                return
            self.tick()


def fly_with_failures(m: MissionMachine, w, events, ticks: int) -> None:
    """Tick the world `ticks` times (or until the mission ends), injecting the (tick, what,
    vehicle) failures: operator abort, silent link, LAND refused, geofence breach, a mode of the
    vehicle's own, or (worlds that fly position targets) a vehicle that does not move."""
    at: dict[int, list] = {}
    for k, what, vid in events:
        at.setdefault(k, []).append((what, vid))
    for k in range(ticks):
        if m.done:
            break
        for what, vid in at.get(k, []):
            if what == "abort":
                m.request_abort("operator")
            elif what == "silent":
                w.silent.add(vid)
            elif what == "reject":
                w.reject.add((vid, Cmd.LAND))
            elif what == "fence":
                w.v[vid] = dataclasses.replace(w.v[vid], position_enu_m=(0.0, 0.0, 99.0))
            elif what == "stuck":
                w.stuck.add(vid)
            else:
                w.v[vid] = dataclasses.replace(w.v[vid], mode="LOITER")
        w.tick()  # THEN World.tick's invariants hold


def machine(ids=(1, 2), **plan) -> MissionMachine:
    return MissionMachine(MissionPlan(duration_s=plan.pop("duration_s", 5.0), rules=RULES, **plan),
                          tuple(ids))


#: What an ArduPilot vehicle on the ground is sent over a whole flight
ARDUPILOT_FROM_THE_GROUND = [Cmd.CONFIGURE, Cmd.READ_PARAMS, Cmd.ARM_MODE, Cmd.ARM, Cmd.TAKEOFF,
                             Cmd.HOLD, Cmd.OFFBOARD, Cmd.LAND]


def test_ardupilot_team_on_the_ground_takes_off_in_guided_brakes_flies_guided_nogps_and_lands():
    # GIVEN two ArduPilot Copters on the ground with GUID_OPTIONS = 8
    m = machine(takeoff_altitude_m=3.0)
    w = World(m, {1: 3, 2: 3}, on_ground=True)
    # WHEN the mission runs to its end
    w.run(40.0)
    # THEN each: parameters read, armed (in GUIDED), NAV_TAKEOFF at 3 m above home, BRAKE before
    # the setpoints start, GUIDED_NOGPS, LAND
    assert m.outcome.exit_code == EXIT_OK, m.outcome
    for vid in (1, 2):
        assert w.cmds(vid) == ARDUPILOT_FROM_THE_GROUND
        assert w.v[vid].mode == "LAND" and w.v[vid].landed and not w.v[vid].armed
    (read,) = [c for c in w.sent if c.cmd is Cmd.READ_PARAMS and c.vehicle_id == 1]
    assert read.names == ("GUID_OPTIONS",)
    assert {c.altitude_m for c in w.sent if c.cmd is Cmd.TAKEOFF} == {3.0}
    assert [n for n in m.notes if n.startswith("phase")] == [
        "phase preflight", "phase arm", "phase takeoff", "phase hold", "phase prime",
        "phase formation", "phase stopping", "phase done"]
    assert w.acted_before_formation == []


def test_position_mode_flies_ardupilot_in_guided_and_needs_no_guid_options():
    # GIVEN two ArduPilot Copters on the ground with GUID_OPTIONS bit 3 clear (thrust read as a
    # climb rate: the law's modes refuse them), flown in position mode
    m = machine(takeoff_altitude_m=3.0, control_mode="position")
    w = World(m, {1: 3, 2: 3}, on_ground=True, guid_options=0.0)
    # WHEN the mission runs to its end
    w.run(40.0)
    # THEN it completes: no parameter read (position setpoints carry no thrust), take off in
    # GUIDED, BRAKE while priming, the formation in GUIDED (not GUIDED_NOGPS, which takes no
    # position target), LAND
    assert m.outcome.exit_code == EXIT_OK, m.outcome
    for vid in (1, 2):
        assert w.cmds(vid) == [Cmd.CONFIGURE, Cmd.ARM_MODE, Cmd.ARM, Cmd.TAKEOFF, Cmd.HOLD,
                               Cmd.OFFBOARD, Cmd.LAND]
        assert w.modes[vid] == ["GUIDED", "BRAKE", "GUIDED", "LAND"]
    assert w.acted_before_formation == []


def test_position_mode_stops_an_ardupilot_vehicle_that_leaves_guided():
    # GIVEN an ArduPilot Copter and a PX4 vehicle in the formation of position mode
    m = machine(duration_s=60.0, control_mode="position")
    w = World(m, {1: 3, 2: 12})
    while m.phase is not Phase.FORMATION:
        w.tick()
    w.run(1.0)
    assert (w.v[1].mode, w.v[2].mode) == ("GUIDED", "OFFBOARD")
    # WHEN the copter switches to GUIDED_NOGPS on its own (the law's mode, not this one)
    w.v[1] = dataclasses.replace(w.v[1], mode="GUIDED_NOGPS")
    w.run(10.0)
    # THEN the flight stops naming the mode it left
    assert m.outcome.exit_code == EXIT_ABORTED
    assert "vehicle 1 (sysid 1): left GUIDED (now GUIDED_NOGPS)" in m.outcome.reason


def test_guid_options_without_bit_3_refuses_to_fly_naming_vehicle_and_fix():
    # GIVEN vehicle 2 with GUID_OPTIONS = 0 (thrust would be read as a climb rate)
    m = machine()
    w = World(m, {1: 3, 2: 3}, on_ground=True)
    w.params[2]["GUID_OPTIONS"] = 0.0
    w.run(20.0)
    # THEN preflight refuses with one line naming vehicle 2 and the fix; nothing is armed
    assert m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason == f"vehicle 2 (sysid 2): GUID_OPTIONS = 0 (bit mask 8 clear); {FIX}"
    assert Cmd.ARM not in w.cmds() and Cmd.OFFBOARD not in w.cmds() and not m.streaming


def test_unanswered_parameter_read_aborts_before_arming():
    m = machine()
    w = World(m, {1: 3, 2: 3}, on_ground=True)
    w.reject.add((1, Cmd.READ_PARAMS))
    w.run(20.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason == "vehicle 1: read_params failed: no"
    assert Cmd.ARM not in w.cmds()


def test_ardupilot_in_actuators_mode_is_refused():
    m = machine(control_mode="actuators")
    w = World(m, {1: 12, 2: 3})
    w.run(20.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason == ("vehicle 2 (sysid 2): ArduPilot Copter does not act on actuators "
                                "setpoints; fly it with --mode attitude or rates")
    assert Cmd.OFFBOARD not in w.cmds()


def test_unknown_autopilot_is_refused():
    m = machine()
    w = World(m, {1: 3, 2: 0})
    w.run(20.0)
    assert m.outcome.reason == unsupported_text("vehicle 2 (sysid 2)", 0)
    assert w.cmds(2) == [Cmd.CONFIGURE, Cmd.LAND]  # alive and airborne: the abort action


def test_mixed_team_each_vehicle_gets_its_own_modes():
    # GIVEN a PX4 vehicle holding and an ArduPilot vehicle in the air still in GUIDED
    m = machine(end_action="hold")
    w = World(m, {1: 12, 2: 3}, in_air_mode="GUIDED")
    while m.phase is not Phase.FORMATION:
        w.tick()
    # THEN only the ArduPilot vehicle was read and sent to BRAKE before priming
    assert w.cmds(1) == [Cmd.CONFIGURE, Cmd.OFFBOARD]
    assert w.cmds(2) == [Cmd.CONFIGURE, Cmd.READ_PARAMS, Cmd.HOLD, Cmd.OFFBOARD]
    assert (w.v[1].mode, w.v[2].mode) == ("OFFBOARD", "GUIDED_NOGPS")
    w.run(20.0)
    assert m.outcome.exit_code == EXIT_OK
    assert (w.v[1].mode, w.v[2].mode) == ("AUTO_LOITER", "BRAKE")
    assert w.acted_before_formation == []


def test_ardupilot_leaving_guided_nogps_on_its_own_aborts():
    m = machine(duration_s=60.0)
    w = World(m, {1: 3, 2: 3})
    while m.phase is not Phase.FORMATION:
        w.tick()
    w.run(1.0)
    w.v[1] = dataclasses.replace(w.v[1], mode="RTL")  # e.g. a failsafe of its own
    w.run(10.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert "vehicle 1 (sysid 1): left GUIDED_NOGPS (now RTL)" in m.outcome.reason


def test_abort_lands_with_the_land_mode_and_streams_until_guided_nogps_is_left():
    m = machine(duration_s=60.0)
    w = World(m, {1: 3, 2: 3})
    while m.phase is not Phase.FORMATION:
        w.tick()
    w.reject.add((2, Cmd.LAND))  # vehicle 2 refuses LAND: it stays in GUIDED_NOGPS
    m.request_abort("interrupted (Ctrl-C)")
    w.run(2.0)
    assert w.v[1].mode == "LAND" and 1 not in m.streaming
    assert w.v[2].mode == "GUIDED_NOGPS" and 2 in m.streaming  # still fed, never abandoned
    w.run(10.0)
    assert m.outcome.exit_code == EXIT_INTERRUPTED
    assert "vehicle 2: land not accepted" in m.outcome.reason


def test_brake_refused_or_never_reported_before_priming_aborts():
    # GIVEN an ArduPilot vehicle in the air in GUIDED that refuses BRAKE
    m = machine(ids=(1,))
    w = World(m, {1: 3}, in_air_mode="GUIDED")
    w.reject.add((1, Cmd.HOLD))
    w.run(10.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason == "vehicle 1: hold failed: no"
    # OR acknowledges it but keeps reporting GUIDED
    m = machine(ids=(1,), hold_timeout_s=2.0)
    w2 = World(m, {1: 3}, in_air_mode="GUIDED")
    w2.ignore.add((1, Cmd.HOLD))
    w2.run(10.0)
    assert m.outcome.reason == "vehicles 1 (BRAKE) did not report their hold mode within 2 s"
    # THEN no setpoint was streamed to a vehicle that would act on it, and no GUIDED_NOGPS
    for world in (w, w2):
        assert Cmd.OFFBOARD not in world.cmds() and world.acted_before_formation == []


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 400), st.sampled_from(["abort", "silent", "reject",
                                                                  "fence", "mode"]),
                          st.sampled_from([1, 2, 3])), max_size=4),
       st.booleans())
def test_mixed_team_invariants_under_random_failures(events, on_ground):
    # GIVEN a PX4 vehicle and two ArduPilot vehicles, random failures at random ticks
    m = machine(ids=(1, 2, 3), duration_s=8.0)
    w = World(m, {1: 12, 2: 3, 3: 3}, on_ground=on_ground)
    fly_with_failures(m, w, events, 1600)
    assert m.done and m.outcome is not None
    assert w.acted_before_formation == []


@pytest.mark.parametrize(("version", "refused"), [((1, 13, 3), False), ((1, 16, 0), True)])
def test_an_actuators_flight_reads_autopilot_version_and_refuses_px4_from_1_14(version, refused):
    # GIVEN two PX4 vehicles in the air, one on PX4 `version`, flown in actuators mode
    m = machine(control_mode="actuators")
    w = World(m, {1: 12, 2: 12})
    w.versions[2] = _version(*version)
    w.run(3.0)
    # THEN preflight asked each for AUTOPILOT_VERSION once
    assert w.cmds(1).count(Cmd.IDENTIFY) == 1 and w.cmds(2).count(Cmd.IDENTIFY) == 1
    if refused:
        # AND refused the flight before commanding anything, naming vehicle 2 and the fix
        assert m.done and m.outcome.exit_code == EXIT_ABORTED
        assert "PX4 1.16.0 ignores SET_ACTUATOR_CONTROL_TARGET" in m.outcome.reason
        assert Cmd.OFFBOARD not in w.cmds()
    else:
        assert Cmd.OFFBOARD in w.cmds()


def test_a_rates_flight_does_not_ask_for_the_version():
    m = machine()
    w = World(m, {1: 12, 2: 12})
    w.run(3.0)
    assert Cmd.IDENTIFY not in w.cmds() and Cmd.OFFBOARD in w.cmds()
