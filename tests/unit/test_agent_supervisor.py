"""The supervisor's sequence over its agents' statuses (its bus recorded, its clock driven)."""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path

import numpy as np
import pytest

from gcs.agent.command import AgentProcesses, add_parser, local_agents_scheduling
from gcs.agent.control import Status
from gcs.agent.supervise import Supervisor
from gcs.agent.table import Rows
from gcs.config import load_team
from gcs.mission.plan import EXIT_ABORTED, EXIT_INTERRUPTED, EXIT_OK

ROOT = Path(__file__).resolve().parents[2]


class Bus:
    """The SupervisorBus calls the supervisor makes, recorded; statuses put in by the test."""

    def __init__(self) -> None:
        self.statuses: dict[int, Status] = {}
        self.status_received_s: dict[int, float] = {}
        self.status_updates: asyncio.Queue = asyncio.Queue()
        self.sent: list[dict] = []

    def open_gate(self, name, at_s=None) -> None:
        self.sent.append({"kind": "gate", "gate": name, "at_s": at_s})

    def abort(self, reason, action) -> None:
        self.sent.append({"kind": "abort", "reason": reason, "action": action})

    def heartbeat(self) -> None:
        self.sent.append({"kind": "heartbeat"})

    def rows(self, ids, now_s) -> Rows:
        k = len(ids)
        return Rows(tuple(ids), np.zeros((k, 3)), np.zeros((k, 3)), np.zeros((k, 3)),
                    np.zeros((k, 4)), np.zeros((k, 3)), np.zeros(k), np.zeros(k), np.zeros(k),
                    np.zeros(k, dtype=bool))


class World:
    def __init__(self, groups) -> None:
        self.team = load_team(ROOT / "configs" / "square4.yaml")
        self.t = 0.0
        self.bus = Bus()
        self.exit: dict[int, int | None] = {}
        self.sup = Supervisor(self.team, self.bus, groups, lambda k: self.exit.get(k),
                              prime_s=1.5, connect_timeout_s=10.0, clock=lambda: self.t)

    def say(self, vehicles, **status) -> None:
        fields = {"phase": "preflight"} | status
        for v in vehicles:
            self.bus.statuses[v] = Status(v, 0, self.t, **fields)
            self.bus.status_received_s[v] = self.t

    def step(self, dt: float = 0.05) -> bool:
        self.t += dt
        return self.sup.step()

    def gates(self, gate: str) -> list[dict]:
        return [m for m in self.bus.sent if m["kind"] == "gate" and m["gate"] == gate]


def test_gates_open_only_when_every_agent_waits_and_the_start_is_agreed_ahead():
    w = World([(1,), (2,), (3, 4)])
    w.say((1,), waiting_gate="flight")
    w.say((2,), waiting_gate="flight")
    w.step()
    assert not w.gates("flight")  # agent 3-4 not heard yet
    w.say((3, 4), waiting_gate="flight")
    w.step()
    assert w.gates("flight")
    for v in ((1,), (2,), (3, 4)):
        w.say(v, phase="hold", waiting_gate="formation")
    w.step()
    (first,) = w.gates("formation")
    # the start: prime_s + the lead ahead, on the supervisor's clock
    assert first["at_s"] == pytest.approx(w.t + 2.5)
    assert any(m["kind"] == "heartbeat" for m in w.bus.sent)


def test_one_agent_stopping_aborts_every_agent_and_the_outcome_names_it():
    w = World([(1,), (2,)])
    w.say((1,), phase="formation")
    w.say((2,), phase="stopping", exit_code=1, outcome="tilt 1.2 rad")
    w.step()
    aborts = [m for m in w.bus.sent if m["kind"] == "abort"]
    assert aborts and "agent of vehicle 2 stopping: tilt 1.2 rad" in aborts[0]["reason"]
    w.say((1,), done=True, exit_code=1, outcome="supervisor: ...")
    w.say((2,), done=True, exit_code=1, outcome="tilt 1.2 rad")
    assert w.step()
    out = w.sup.outcome()
    assert out.exit_code == EXIT_ABORTED and "tilt 1.2 rad" in out.reason


def test_a_silent_agent_or_one_that_exits_without_an_outcome_aborts_the_others():
    w = World([(1,), (2,)])
    w.say((1,), phase="formation")
    w.say((2,), phase="formation")
    w.step()
    for _ in range(30):  # agent 2 silent for 1.5 s (network.stale_after_s 1 s)
        w.say((1,), phase="formation")
        w.step()
    aborts = [m for m in w.bus.sent if m["kind"] == "abort"]
    assert aborts and "agent of vehicle 2 silent for" in aborts[0]["reason"]
    w2 = World([(1,), (2,)])
    w2.say((1,), phase="formation")
    w2.say((2,), phase="formation")
    w2.exit[1] = -9
    w2.step()
    assert "exited with status -9 without an outcome" in w2.sup.aborted


def test_a_clean_team_ends_with_exit_0_and_ctrl_c_with_130():
    w = World([(1,), (2,)])
    for v in ((1,), (2,)):
        w.say(v, phase="done", done=True, exit_code=0, outcome="formation complete")
    assert w.step()
    assert w.sup.outcome().exit_code == EXIT_OK
    w2 = World([(1,)])
    w2.say((1,), phase="formation")
    w2.step()
    w2.sup.interrupt()
    assert [m for m in w2.bus.sent if m["kind"] == "abort"]
    w2.say((1,), phase="done", done=True, exit_code=130, outcome="abort")
    assert w2.step()
    assert w2.sup.outcome().exit_code == EXIT_INTERRUPTED


def test_the_team_formation_check_is_the_supervisors():
    # GIVEN a formation started whose error (from the states on the bus) stays at 5 m
    w = World([(1,), (2,), (3,), (4,)])
    for v in (1, 2, 3, 4):
        w.say((v,), phase="hold", waiting_gate="formation")
    w.step()
    offsets = w.team.offsets_enu_m()

    def rows(ids, now_s):
        k = len(ids)
        pos = offsets.copy()
        pos[0] += [5.0, 0.0, 0.0]
        return Rows(tuple(ids), pos, np.zeros((k, 3)), np.zeros((k, 3)), np.zeros((k, 4)),
                    np.zeros((k, 3)), np.zeros(k), np.zeros(k), np.zeros(k),
                    np.ones(k, dtype=bool))

    w.bus.rows = rows
    for _ in range(int(9.0 / 0.05)):  # until t = 10 s nothing happens
        for v in (1, 2, 3, 4):
            w.say((v,), phase="formation")
        w.step()
    assert w.sup.aborted is None
    for _ in range(int(4.0 / 0.05)):
        for v in (1, 2, 3, 4):
            w.say((v,), phase="formation")
        w.step()
    # THEN after fly.formation_check_s the supervisor stops the team, naming the rule
    assert "do not follow the formation" in w.sup.aborted
    assert "(fly.formation_check)" in w.sup.aborted


@pytest.mark.parametrize(("policy", "agents", "cores", "expected"), [
    ("auto", 4, 2, "normal"),  # four agents fill both cores: none takes real time
    ("auto", 2, 2, "normal"),
    ("auto", 1, 2, None),  # one agent process (--agents-per-process 4) leaves a core
    ("auto", 4, 8, None),
    ("auto", 1, None, "normal"),  # cores unknown: one
    ("realtime", 4, 2, None),  # asked for in the file: the file's
    ("normal", 4, 2, None),
])
def test_local_agents_that_fill_the_cores_start_normally_scheduled(policy, agents, cores,
                                                                   expected):
    assert local_agents_scheduling(policy, agents, cores) == expected


def test_started_agents_are_given_the_scheduling_and_an_agent_takes_it(tmp_path, monkeypatch):
    started = []

    class Popen:
        def __init__(self, argv, **_):
            started.append(argv)

    monkeypatch.setattr("gcs.agent.command.subprocess.Popen", Popen)
    args = argparse.Namespace(mode=None, duration_s=None, no_figures=True)
    AgentProcesses(Path("team.yaml"), [(1,), (2,)], tmp_path, args, "normal")
    AgentProcesses(Path("team.yaml"), [(3,)], tmp_path, args)
    assert [a[a.index("--scheduling") + 1] for a in started[:2]] == ["normal", "normal"]
    assert "--scheduling" not in started[2]
    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    parsed = parser.parse_args(started[0][3:])
    assert parsed.scheduling == "normal" and parsed.ids == [1]
    with pytest.raises(SystemExit):
        parser.parse_args(["agent", "--team", "t.yaml", "--id", "1", "--scheduling", "fast"])
