"""The mission machine's team gates: a machine that flies part of a team (gcs agent) waits at
GATE_FLIGHT and GATE_FORMATION until the team's supervisor opens them."""

from __future__ import annotations

from test_mission import IDS, RULES, World

from gcs.config.modes import FlyAction
from gcs.mission.machine import Cmd, MissionMachine, MissionPlan, Phase
from gcs.mission.plan import EXIT_ABORTED, GATE_FLIGHT, GATE_FORMATION, GATES


def gated(on_ground: bool = False, **plan) -> tuple[MissionMachine, World]:
    m = MissionMachine(MissionPlan(duration_s=plan.pop("duration_s", 5.0), rules=RULES,
                                   gates=frozenset(GATES), **plan), IDS)
    return m, World(m, on_ground=on_ground)


def test_a_gated_machine_arms_nobody_until_the_flight_gate_opens():
    # GIVEN a team on the ground whose preflight passes
    m, w = gated(on_ground=True)
    w.run(20.0)
    # THEN it waits at the flight gate, configured but with nothing armed or moved
    assert m.waiting_at == GATE_FLIGHT and m.phase is Phase.PREFLIGHT
    assert not {Cmd.ARM, Cmd.ARM_MODE, Cmd.TAKEOFF, Cmd.OFFBOARD} & {c for _, c in w.sent}
    # WHEN the gate opens, THEN the vehicles arm and take off, and wait at the formation gate
    m.open_gate(GATE_FLIGHT)
    w.run(20.0)
    assert [c for _, c in w.sent].count(Cmd.TAKEOFF) == len(IDS)
    assert m.waiting_at == GATE_FORMATION and m.phase is not Phase.PRIME
    assert not m.streaming and Cmd.OFFBOARD not in {c for _, c in w.sent}


def test_the_formation_starts_at_the_agreed_time_not_after_prime_s():
    m, w = gated(prime_s=1.5)
    m.open_gate(GATE_FLIGHT)
    w.run(3.0)
    assert m.waiting_at == GATE_FORMATION
    # WHEN the supervisor agrees on a start 4 s from now (longer than prime_s)
    at = w.t + 4.0
    m.open_gate(GATE_FORMATION, at)
    w.run(3.5)
    # THEN PRIME streams and nobody is switched to offboard before the agreed time
    assert m.phase is Phase.PRIME and m.streaming and m.formation_t0_s is None
    w.run(1.0)
    assert m.phase is Phase.FORMATION
    assert at <= m.formation_t0_s < at + 0.1
    w.run(30.0)
    assert m.done and m.outcome.exit_code == 0


def test_an_abort_with_an_action_gives_every_vehicle_that_action():
    # GIVEN a formation in flight; WHEN the team around the machine is lost (supervisor or
    # a neighbour), with the link-loss action hold
    m, w = gated(duration_s=30.0, abort_action=FlyAction.LAND, link_loss_action=FlyAction.HOLD)
    m.open_gate(GATE_FLIGHT)
    m.open_gate(GATE_FORMATION)
    w.run(5.0)
    assert m.phase is Phase.FORMATION
    m.request_abort("lost the supervisor", operator=False, action=FlyAction.HOLD)
    w.run(10.0)
    # THEN every vehicle is held, none landed, and the outcome says why
    sent = [c for _, c in w.sent]
    assert sent.count(Cmd.HOLD) == len(IDS) and Cmd.LAND not in sent
    assert m.outcome.exit_code == EXIT_ABORTED and "lost the supervisor" in m.outcome.reason


def test_an_ungated_plan_never_waits():
    m = MissionMachine(MissionPlan(duration_s=2.0, rules=RULES), IDS)
    w = World(m)
    w.run(20.0)
    assert m.done and m.outcome.exit_code == 0 and m.waiting_at is None
