"""The go-to-start phase (issue 9, point 4): the mission machine's GOTO (pure: time and telemetry
are arguments), its two-leg order and settle rule (gcs.mission.goto), and the team file's
`fly.go_to_start` block."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from test_autopilots import ARDUPILOT_FROM_THE_GROUND, RULES, World, fly_with_failures

from gcs.config import ConfigError, check_go_to_start, team_from_dict
from gcs.fly.setup import go_to_start_plan
from gcs.mission.goto import (
    GoToStart,
    GoToStartPlan,
    carrot_arrival_s,
    carrot_travel_m,
    crossing_pairs,
)
from gcs.mission.machine import (
    EXIT_ABORTED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    Cmd,
    Command,
    MissionMachine,
    MissionPlan,
    Phase,
)

ROOT = Path(__file__).resolve().parents[2]
STARTS = {1: (0.0, 6.0, 6.0), 2: (7.0, -5.0, 8.0), 3: (-4.0, 1.0, 7.0)}
STEP_M = 0.25  # the fake vehicles fly 5 m/s at the machine's 20 Hz


def goto_plan(enabled: str = "auto", ids=(1, 2), **kw) -> GoToStartPlan:
    return GoToStartPlan(tuple((vid, STARTS[vid]) for vid in ids), enabled, **kw)


def machine(ids=(1, 2), enabled: str = "auto", goto: dict | None = None, **plan) -> MissionMachine:
    return MissionMachine(MissionPlan(
        duration_s=plan.pop("duration_s", 5.0), rules=RULES,
        go_to_start=goto_plan(enabled, ids, **(goto or {})), **plan), tuple(ids))


class Flying(World):
    """test_autopilots' fake team, flying position targets: the profile's position mode (PX4
    OFFBOARD, ArduPilot GUIDED) moves a vehicle STEP_M per tick towards its target while it gets
    one; it records the team's positions and when each vehicle first got a target."""

    def __init__(self, m: MissionMachine, autopilots: dict[int, int], **kw) -> None:
        super().__init__(m, autopilots, **kw)
        self.stuck: set[int] = set()  # vehicles that do not move
        self.first_target_s: dict[int, float] = {}
        self.position_mode_s: dict[int, float] = {}
        self.track: list[tuple[float, dict[int, tuple[float, float, float]]]] = []
        self.after_stop: dict[int, list[str]] = {}  # modes seen while getting targets, stopping

    def _obey(self, c: Command, s):
        if c.cmd is Cmd.POSITION_MODE and (c.vehicle_id, c.cmd) not in self.reject:
            self.position_mode_s[c.vehicle_id] = self.t
            return dataclasses.replace(s, mode="GUIDED" if s.autopilot == 3 else "OFFBOARD"), \
                True, ()
        return super()._obey(c, s)

    def tick(self, dt: float = 0.05) -> None:
        targets = self.m.position_targets
        for vid, (target, _) in targets.items():
            self.first_target_s.setdefault(vid, self.t)
            s = self.v[vid]
            if self.m.phase is Phase.STOPPING:
                self.after_stop.setdefault(vid, []).append(s.mode)
            if s.mode != self.m.profile(vid).position_mode.name or vid in self.stuck:
                continue
            d = [b - a for a, b in zip(s.position_enu_m, target, strict=True)]
            n = math.sqrt(sum(x * x for x in d))
            k = min(1.0, STEP_M / n) if n > 0 else 0.0
            p = tuple(a + k * x for a, x in zip(s.position_enu_m, d, strict=True))
            v = tuple(k * x / dt for x in d)
            self.v[vid] = dataclasses.replace(s, position_enu_m=p, velocity_enu_mps=v)
        for vid in self.v:
            if vid not in targets and any(self.v[vid].velocity_enu_mps):
                self.v[vid] = dataclasses.replace(self.v[vid], velocity_enu_mps=(0.0, 0.0, 0.0))
        self.track.append((self.t, {vid: s.position_enu_m for vid, s in self.v.items()}))
        super().tick(dt)

    def at_formation_start(self) -> dict[int, tuple[float, float, float]]:
        t0 = self.m.formation_t0_s
        return next(p for t, p in self.track if t >= t0 - 1e-9)


def phases(m: MissionMachine) -> list[str]:
    return [n for n in m.notes if n.startswith("phase")]


def test_px4_team_from_the_ground_goes_to_start_then_holds_and_flies_from_there():
    # GIVEN two PX4 vehicles on the ground at (3, 0) and (6, 0), go-to-start on (auto)
    m = machine(takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12, 2: 12}, on_ground=True)
    # WHEN the mission runs
    w.run(80.0)
    # THEN take off, go to start (OFFBOARD with position setpoints), hold, prime, formation
    assert m.outcome.exit_code == EXIT_OK, m.outcome
    assert phases(m) == ["phase preflight", "phase arm", "phase takeoff", "phase goto",
                         "phase hold", "phase prime", "phase formation", "phase stopping",
                         "phase done"]
    for vid in (1, 2):
        assert w.cmds(vid) == [Cmd.CONFIGURE, Cmd.ARM_MODE, Cmd.ARM, Cmd.TAKEOFF,
                               Cmd.POSITION_MODE, Cmd.HOLD, Cmd.OFFBOARD, Cmd.LAND]
        # AND the setpoints streamed (lead_s) before OFFBOARD was asked for
        assert w.position_mode_s[vid] - w.first_target_s[vid] >= 0.5 - 1e-9
    # AND the formation started with every vehicle at its start (the law's t = 0)
    p0 = w.at_formation_start()
    for vid in (1, 2):
        assert math.dist(p0[vid], STARTS[vid]) <= 0.3
    results = m.goto_results
    assert set(results) == {1, 2} and all(r.settled for r in results.values())
    assert results[2].target_enu_m == STARTS[2] and results[2].error_m <= 0.3
    # AND the log says where each went and when all settled
    assert "vehicle 2 (sysid 2): going to start (7.00, -5.00, 8.00) m, 7.5 m away" in m.notes
    assert any(n.startswith("go to start: all 2 vehicles settled at their start positions after")
               and "(within 0.3 m; largest mean error" in n for n in m.notes)


def test_the_team_climbs_to_its_start_altitudes_before_anyone_flies_across():
    m = machine(takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12, 2: 12}, on_ground=True)
    w.run(80.0)
    # GIVEN the recorded flight WHEN the first vehicle left its take-off column
    moved = [t for t, p in w.track
             if any(math.hypot(p[vid][0] - 3.0 * vid, p[vid][1]) > 1e-6 for vid in (1, 2))]
    t_across = moved[0]
    # THEN every vehicle was within tolerance of its own start altitude by then
    before = [p for t, p in w.track if t < t_across][-1]
    for vid in (1, 2):
        assert abs(before[vid][2] - STARTS[vid][2]) <= 0.3


def test_ardupilot_goes_to_start_in_guided_without_a_mode_change():
    # GIVEN two ArduPilot copters on the ground: their takeoff leaves them in GUIDED
    m = machine(takeoff_altitude_m=2.5)
    w = Flying(m, {1: 3, 2: 3}, on_ground=True)
    w.run(80.0)
    # THEN position targets in GUIDED (no mode command), then BRAKE, GUIDED_NOGPS, LAND
    assert m.outcome.exit_code == EXIT_OK, m.outcome
    assert w.cmds(1) == w.cmds(2) == ARDUPILOT_FROM_THE_GROUND  # what it was without the phase
    p0 = w.at_formation_start()
    assert all(math.dist(p0[vid], STARTS[vid]) <= 0.3 for vid in (1, 2))
    assert w.acted_before_formation == []


@pytest.mark.parametrize(("enabled", "goes"), [("auto", False), ("true", True), ("false", False)])
def test_a_team_already_in_the_air_goes_to_start_only_when_asked(enabled, goes):
    # GIVEN a PX4 team holding in the air (the emulator's scenario starts)
    m = machine(enabled=enabled)
    w = Flying(m, {1: 12, 2: 12})
    w.run(60.0)
    # THEN auto and false leave it where it is (the law starts there), true flies it to start
    assert m.outcome.exit_code == EXIT_OK, m.outcome
    assert ("phase goto" in phases(m)) is goes
    assert (Cmd.POSITION_MODE in w.cmds()) is goes


def test_a_vehicle_that_does_not_get_there_stops_the_flight_at_the_timeout_naming_it():
    # GIVEN vehicle 2 that takes the position mode but does not move
    m = machine(takeoff_altitude_m=2.5, goto={"timeout_s": 20.0})
    w = Flying(m, {1: 12, 2: 12}, on_ground=True)
    w.stuck.add(2)
    w.run(80.0)
    # THEN after 20 s the flight stops, exit 1, one line per vehicle not settled
    assert m.outcome.exit_code == EXIT_ABORTED
    reason = m.outcome.reason
    assert reason.startswith("not every vehicle settled at its start position within 20 s "
                             "(fly.go_to_start.timeout_s):\n  vehicle ")
    assert ("vehicle 2 (sysid 2): 7.50 m from its start (7.00, -5.00, 8.00) m (need <= 0.3 m "
            "and <= 0.1 m/s; climb leg)") in reason
    # AND both were landed (abort_action), no law setpoint was ever sent
    assert Cmd.OFFBOARD not in w.cmds() and w.cmds(2)[-1] is Cmd.LAND
    assert m.formation_t0_s is None and not m.goto_results[2].settled


def test_settled_means_mean_position_within_tolerance_and_no_drift_over_settle_s():
    plan = goto_plan(ids=(1,), settle_s=2.0)
    g = GoToStart.begin(plan, 0.0, {1: (0.0, 6.0, 2.5)})
    # climb first, over where it was: 3.5 m, too short to reach 2 m/s and stop at 0.5 m/s^2, so
    # the setpoint starts at sqrt(2 a L) and slows down to stop on the start altitude
    v0 = math.sqrt(3.5)
    assert g.target(1, 0.0)[0] == (0.0, 6.0, 2.5)
    p1, v1 = g.target(1, 1.0)
    assert p1[2] == pytest.approx(2.5 + v0 - 0.25) and v1[2] == pytest.approx(v0 - 0.5, abs=0.01)
    assert g.target(1, 2.0 * v0) == g.target(1, 9.0) == ((0.0, 6.0, 6.0), (0.0, 0.0, 0.0))
    assert not g.update(0.1, {1: (0.0, 6.0, 5.9)}, {1: (0.0, 0.0, 0.0)})
    # THEN across, from over the entry point at the start altitude (here: the start itself)
    assert g.stage == "across" and g.target(1, 0.1)[0] == STARTS[1]
    x, y, z = STARTS[1]
    # GIVEN a vehicle that jitters around its start (0.25 m, 0.3 m/s samples, mean zero)
    def jitter(t: float) -> tuple[dict, dict]:
        sign = 1.0 if round(t * 20) % 2 else -1.0
        return {1: (x + 0.25 * sign, y, z)}, {1: (0.3 * sign, 0.0, 0.0)}
    ticks = [1.0 + k * 0.05 for k in range(41)]
    # THEN it is settled once the window spans settle_s (2 s), not before
    assert not any(g.update(t, *jitter(t)) for t in ticks[:-1])
    assert g.update(ticks[-1], *jitter(ticks[-1]))
    assert g.results[1].settled and g.results[1].duration_s == pytest.approx(3.0)
    assert g.results[1].error_m < 0.02 and g.results[1].speed_mps < 0.02
    # AND a vehicle drifting at 0.25 m/s through its start, or holding 0.4 m off it, is not
    for p_of_t, v in ((lambda t: (x + 0.25 * (t - 2.0), y, z), (0.25, 0.0, 0.0)),
                      (lambda t: (x, y + 0.4, z), (0.0, 0.0, 0.0))):
        g = GoToStart.begin(plan, 0.0, {1: STARTS[1]})
        g.update(0.05, {1: STARTS[1]}, {1: (0.0, 0.0, 0.0)})
        assert not any(g.update(t, {1: p_of_t(t)}, {1: v}) for t in ticks)


def _circling(bias_m: float, radius_m: float, period_s: float = 12.0):
    """A vehicle holding its start as PX4 SIH holds a position setpoint: a slow wander (here a
    horizontal circle, 0.18 m/s at 0.35 m, which no 2 s window sees as still) about a point
    ``bias_m`` east of its start."""
    x, y, z = STARTS[1]
    w = 2.0 * math.pi / period_s

    def at(t: float) -> tuple[dict, dict]:
        return ({1: (x + bias_m + radius_m * math.cos(w * t), y + radius_m * math.sin(w * t), z)},
                {1: (-radius_m * w * math.sin(w * t), radius_m * w * math.cos(w * t), 0.0)})
    return at


def _hold(at, until_s: float) -> tuple[GoToStart, float | None]:
    g = GoToStart.begin(goto_plan(ids=(1,)), 0.0, {1: STARTS[1]})
    g.update(0.05, {1: STARTS[1]}, {1: (0.0, 0.0, 0.0)})  # already at the start altitude
    assert g.stage == "across"
    for k in range(2, int(until_s / 0.05)):
        if g.update(k * 0.05, *at(k * 0.05)):
            return g, k * 0.05
    return g, None


def test_a_vehicle_wandering_as_px4_holds_is_settled_by_the_hold_rule_after_its_rest():
    # GIVEN a vehicle whose setpoint rests on its start from t = 0.05 s (no leg to fly) and that
    # wanders 0.35 m about a point 0.1 m off it (SIH: 0.32-0.38 m RMS, 0.05-0.14 m off)
    g, settled_s = _hold(_circling(0.1, 0.35), 40.0)
    # THEN the still rule never holds (2 s drift 0.17 m/s), the hold rule does once the rest has
    # lasted HOLD_S (8 s) and its halves no longer drift (by 12 s, one turn of the wander)
    assert settled_s is not None and 8.0 <= settled_s <= 12.5
    r = g.results[1]
    assert r.settled and r.rule == "holding" and r.wander_m == pytest.approx(0.35, abs=0.03)
    assert r.error_m < 0.3 and r.speed_mps <= 0.1
    assert "by the hold rule" in g.settled_line() and "largest wander 0.3" in g.settled_line()


@pytest.mark.parametrize(("bias_m", "radius_m", "why"), [
    (0.8, 0.35, "mean 0.8"),  # rests 0.8 m away: further than its wander explains
    (0.1, 0.7, "wander 0.69 m"),  # swings 0.7 m: more than MAX_WANDER_M
])
def test_a_vehicle_that_is_not_there_is_not_settled_by_its_wander(bias_m, radius_m, why):
    at = _circling(bias_m, radius_m)
    g, settled_s = _hold(at, 40.0)
    assert settled_s is None
    (line,) = g.not_settled_lines(40.0, {1: "vehicle 1 (sysid 1)"}, at(40.0)[0])
    assert why in line and "at rest: mean" in line and "wander <= 0.6 m" in line
    assert not g.results[1].settled and g.results[1].rule == ""


def test_the_carrot_comes_to_rest_when_its_travel_reaches_the_leg_end():
    for length in (0.5, 3.5, 10.0):
        t = carrot_arrival_s(length, 2.0, 0.5)
        assert carrot_travel_m(length, 2.0, 0.5, t) == pytest.approx(length)
        assert carrot_travel_m(length, 2.0, 0.5, t - 0.05) < length - 1e-4


def test_the_carrot_cruises_then_slows_down_to_stop_at_the_end_of_the_leg():
    # GIVEN 10 m at 2 m/s, slowing at 0.5 m/s^2: 3 s of cruise (6 m), then 4 s of braking (4 m)
    travel = [carrot_travel_m(10.0, 2.0, 0.5, k * 0.01) for k in range(1000)]
    assert carrot_travel_m(10.0, 2.0, 0.5, 3.0) == pytest.approx(6.0)
    assert carrot_travel_m(10.0, 2.0, 0.5, 5.0) == pytest.approx(6.0 + 4.0 - 1.0)
    assert carrot_travel_m(10.0, 2.0, 0.5, 7.0) == pytest.approx(10.0)
    # THEN it never goes back, never beyond the end, never faster than 2 m/s or a jump in speed
    speeds = [(b - a) / 0.01 for a, b in zip(travel, travel[1:], strict=False)]
    assert min(speeds) >= 0.0 and max(travel) <= 10.0 and max(speeds) <= 2.0 + 1e-9
    assert max(abs(b - a) for a, b in zip(speeds, speeds[1:], strict=False)) <= 0.5 * 0.01 + 1e-9


def test_crossing_legs_are_named_only_at_similar_altitudes():
    entries = {1: (0.0, 0.0, 2.5), 2: (10.0, 0.0, 2.5)}
    # GIVEN legs that cross (x) at the same altitude THEN named; 3 m apart in altitude: not
    assert crossing_pairs(entries, {1: (10.0, 10.0, 5.0), 2: (0.0, 10.0, 5.0)}, 1.0) == [
        (1, 2, 0.0)]
    assert crossing_pairs(entries, {1: (10.0, 10.0, 5.0), 2: (0.0, 10.0, 8.0)}, 1.0) == []
    assert crossing_pairs(entries, {1: (0.0, 10.0, 5.0), 2: (10.0, 10.0, 5.0)}, 1.0) == []


def test_operator_abort_in_goto_lands_and_streams_until_offboard_is_left():
    # GIVEN a PX4 vehicle flying to its start in OFFBOARD
    m = machine(ids=(1,), takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12}, on_ground=True)
    while not (m.phase is Phase.GOTO and w.v[1].mode == "OFFBOARD"):
        w.tick()
    # WHEN the operator aborts (Ctrl-C) and the vehicle acknowledges LAND but stays in OFFBOARD
    w.ignore.add((1, Cmd.LAND))
    m.request_abort("interrupted (Ctrl-C)")
    for _ in range(20):
        w.tick()
    # THEN it keeps getting position setpoints (World.tick checks it every tick) ...
    assert m.phase is Phase.STOPPING and 1 in m.position_targets
    assert set(w.after_stop[1]) == {"OFFBOARD"}
    # ... until it reports another mode; then it lands, exit 130, no law setpoint ever
    w.v[1] = dataclasses.replace(w.v[1], mode="AUTO_LAND", landed=True, armed=False,
                                 landed_state=1)
    w.run(30.0)
    assert m.outcome.exit_code == EXIT_INTERRUPTED
    assert w.cmds(1)[-1] is Cmd.LAND and Cmd.OFFBOARD not in w.cmds(1)
    assert not m.position_targets and not m.streaming


def test_a_stop_while_offboard_is_pending_still_streams_position_setpoints():
    # GIVEN a PX4 vehicle whose OFFBOARD answer is late (the command stays outstanding)
    m = machine(ids=(1,), takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12}, on_ground=True)
    held: list = []
    real_apply = w.apply

    def apply(cmds) -> None:
        held.extend(c for c in cmds if c.cmd is Cmd.POSITION_MODE)
        real_apply([c for c in cmds if c.cmd is not Cmd.POSITION_MODE])

    w.apply = apply
    while not held:
        w.tick()
    # WHEN the vehicle enters OFFBOARD and the operator aborts before the ACK is read
    w.v[1] = dataclasses.replace(w.v[1], mode="OFFBOARD")
    m.request_abort("abort key pressed")
    for _ in range(10):
        w.tick()  # World.tick: OFFBOARD -> it must be getting position setpoints
        assert 1 in m.position_targets
    # THEN once the ACK arrives the stop goes on: LAND, and the stream ends after it left
    w.apply = real_apply
    w.apply([held[0]])
    w.run(30.0)
    assert m.outcome.exit_code == EXIT_INTERRUPTED and w.cmds(1)[-1] is Cmd.LAND


def test_leaving_offboard_during_the_go_to_start_stops_the_flight():
    m = machine(takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12, 2: 12}, on_ground=True)
    while not (m.phase is Phase.GOTO and w.v[1].mode == "OFFBOARD"):
        w.tick()
    w.tick()
    # WHEN PX4's failsafe takes vehicle 1 out of OFFBOARD
    w.v[1] = dataclasses.replace(w.v[1], mode="AUTO_LAND")
    w.run(30.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert "vehicle 1 (sysid 1): left OFFBOARD during the go-to-start (now AUTO_LAND)" in \
        m.outcome.reason


def test_a_refused_position_mode_stops_the_flight():
    m = machine(takeoff_altitude_m=2.5)
    w = Flying(m, {1: 12, 2: 12}, on_ground=True)
    w.reject.add((2, Cmd.POSITION_MODE))
    w.run(40.0)
    assert m.outcome.exit_code == EXIT_ABORTED
    assert m.outcome.reason == "vehicle 2: position_mode failed: no"


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 900), st.sampled_from(["abort", "silent", "reject",
                                                                  "fence", "mode", "stuck"]),
                          st.sampled_from([1, 2, 3])), max_size=4),
       st.sampled_from(["auto", "true"]), st.booleans())
def test_never_offboard_without_setpoints_through_the_go_to_start(events, enabled, on_ground):
    # GIVEN a PX4 vehicle and two ArduPilot vehicles going to their starts, random failures at
    # random ticks THEN World.tick's invariants hold (a vehicle in OFFBOARD always gets position
    # or law setpoints, never both) and the mission ends
    m = machine(ids=(1, 2, 3), enabled=enabled, duration_s=8.0, takeoff_altitude_m=2.5,
                goto={"timeout_s": 25.0})
    w = Flying(m, {1: 12, 2: 3, 3: 3}, on_ground=on_ground)
    fly_with_failures(m, w, events, 3000)
    assert m.done and m.outcome is not None
    assert w.acted_before_formation == []


# --- the team file ---------------------------------------------------------------------------


def square4(**fly) -> dict:
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["fly"].update(fly)
    return data


def test_go_to_start_defaults_and_block():
    team = team_from_dict(square4())
    g = team.fly.go_to_start
    assert (g.enabled, g.tolerance_m, g.max_speed_mps, g.settle_s, g.timeout_s,
            g.cruise_speed_mps, g.min_altitude_m) == ("auto", 0.3, 0.1, 2.0, 60.0, 2.0, 2.0)
    team = team_from_dict(square4(go_to_start={"enabled": True, "tolerance_m": 0.5}))
    assert team.fly.go_to_start.enabled == "true" and team.fly.go_to_start.tolerance_m == 0.5
    plan = go_to_start_plan(team)
    assert plan.start_of(3) == (-5.0, -4.0, 12.0) and plan.tolerance_m == 0.5
    assert go_to_start_plan(team_from_dict(square4(go_to_start={"enabled": False}))) is None


@pytest.mark.parametrize(("block", "message"), [
    ({"enabled": "maybe"}, r"fly\.go_to_start\.enabled: expected one of 'auto', 'true', 'false'"),
    ({"tolerance_m": 0.0}, r"fly\.go_to_start\.tolerance_m: expected > 0, got 0\.0"),
    ({"settle_s": -1}, r"fly\.go_to_start\.settle_s: expected >= 0, got -1\.0"),
    ({"cruise_speed_mps": 50}, r"fly\.go_to_start\.cruise_speed_mps: expected a value in \(0, 20\], got 50\.0"),
    ({"timout_s": 5}, r"fly\.go_to_start\.timout_s: unknown key; did you mean 'timeout_s'\?"),
])
def test_a_bad_go_to_start_block_names_the_key(block, message):
    with pytest.raises(ConfigError, match=message):
        team_from_dict(square4(go_to_start=block), "team.yaml")


def test_a_start_position_below_the_safe_altitude_or_outside_the_fence_is_refused():
    data = square4()
    data["vehicles"][2]["initial"]["position_enu_m"] = [-5.0, -4.0, 0.0]
    team = team_from_dict(data, "team.yaml")  # gcs sim flies it as it is
    with pytest.raises(ConfigError, match=(
            r"^team\.yaml: vehicles\[2\]\.initial\.position_enu_m: vehicle 3 \(sysid 3\): start "
            r"altitude z = 0 m is below fly\.go_to_start\.min_altitude_m 2: ")):
        check_go_to_start(team)
    data["vehicles"][2]["initial"]["position_enu_m"] = [-5.0, -70.0, 12.0]
    with pytest.raises(ConfigError, match=(
            r"vehicles\[2\]\.initial\.position_enu_m: vehicle 3 \(sysid 3\): start position "
            r"y = -70 m is outside fly\.geofence \[-60, 60\] m$")):
        check_go_to_start(team_from_dict(data, "team.yaml"))
    # AND with the phase off nothing is asked of the start positions
    data["fly"]["go_to_start"] = {"enabled": False}
    check_go_to_start(team_from_dict(data, "team.yaml"))
