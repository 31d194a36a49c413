"""A team with no central law: `gcs fly --agents` starts one real `gcs agent` process per vehicle
against a real `vehicle-emu --fleet`, the agents exchange their states over a real Zenoh bus on
127.0.0.1, and the supervisor merges their records. Compared with `gcs fly` flying the same team
file against the same emulator (docs/agents.md, "Measured")."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from pymavlink import mavutil
from test_fly_emulator import emulators, series, team_file

from tests.harness import free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(600)]


def with_network(path: Path, duration_s: float | None = None, clocks: str = "measured"
                 ) -> Path:
    """The team file with its bus on free TCP ports (supervisor base, agent i base + i), the
    law at 50 Hz, `clocks` its network.clocks.

    Four agents, the vehicles' stand-in and the supervisor share this machine's two cores,
    where a real team gives each agent a companion computer and each autopilot its own
    processor. An agent at 100 Hz costs about 0.35 of a core here (its report's cpu_s), so four
    at SCHED_FIFO (fly.scheduling auto) take 1.4 cores ahead of the stand-in, which then answers
    TIMESYNC 0.3 s late and the agents rightly stop. At 50 Hz they take about 0.7; both flights
    of a comparison use the same file."""
    data = yaml.safe_load(path.read_text())
    data["network"] = {"base_port": free_udp_port_block(6, kind=socket.SOCK_STREAM),
                       "clocks": clocks}
    data["fly"]["rates"]["tick_rate_hz"] = 50
    if duration_s is not None:
        data["mission"]["duration_s"] = duration_s
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def gcs_fly(team: Path, out: Path, *args: str, timeout_s: float = 300.0
            ) -> tuple[int, str, str]:
    proc = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out", str(out),
         "--no-figures", "--status", "plain", *args],
        capture_output=True, text=True, timeout=timeout_s,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    return proc.returncode, proc.stdout, proc.stderr


def after(report: dict, key: str, t0: float = 30.0) -> np.ndarray:
    t, v = series(report, key)
    return v[t >= t0]


def mass_at(report: dict, t_s: float) -> np.ndarray:
    t = np.array(report["t_s"])
    est = np.array(report["mass_estimate_kg"], dtype=float)
    rows = np.flatnonzero(np.isfinite(est).all(axis=1))
    return est[rows[np.argmin(np.abs(t[rows] - t_s))]]


@pytest.mark.alone
def test_four_agents_fly_scenario_one_as_the_central_ground_station_does(tmp_path):
    # GIVEN Scenario I (rates mode) on the paper's nominal vehicles (the px4 personality's
    # comparison, whose flights differ from one another by more than 10 %, is measured over
    # several flights by benchmarks/bench_agents.py: docs/benchmarks.md, "Agents")
    autopilot = "nominal"
    bind = free_udp_port_block(4)
    team = with_network(team_file(tmp_path, bind, duration_s=40.0, autopilot=autopilot))
    # WHEN gcs fly flies it, then four agents under gcs fly --agents (fresh emulators each)
    results = {}
    for how, args in (("central", ("--mode", "rates")), ("agents", ("--mode", "rates",
                                                                     "--agents"))):
        with emulators(team, bind, tmp_path):
            code, out, err = gcs_fly(team, tmp_path / how, *args)
        assert code == 0, f"{how}: exit {code}\n{out}\n{err[-4000:]}"
        results[how] = json.loads((tmp_path / how / "report.json").read_text())
    central, agents = results["central"], results["agents"]
    # THEN the agents' team flew as the central one: formation error for t >= 30 s and the
    # mass estimates at 20 s within 10 % (or 0.005 m / 0.005 kg)
    e_c, e_a = after(central, "formation_error_m"), after(agents, "formation_error_m")
    m_c, m_a = mass_at(central, 20.0), mass_at(agents, 20.0)
    print(f"t >= 30 s mean / max: central {np.nanmean(e_c):.4f} / {np.nanmax(e_c):.4f} m, "
          f"agents {np.nanmean(e_a):.4f} / {np.nanmax(e_a):.4f} m; masses at 20 s differ "
          f"by at most {100 * np.max(np.abs(m_a / m_c - 1)):.2f} %")
    for stat in (np.nanmean, np.nanmax):
        assert abs(stat(e_a) - stat(e_c)) <= max(0.1 * stat(e_c), 0.005), (stat, e_a, e_c)
    np.testing.assert_allclose(m_a, m_c, rtol=0.1, atol=0.005)
    # the merged report has every vehicle, and every agent measured its neighbours' ages
    assert [v["id"] for v in agents["vehicles"]] == [1, 2, 3, 4]
    extra = agents["extra"]["agents"]
    assert {k for k in extra if k.startswith("agent of")} == {
        f"agent of vehicle {v}" for v in (1, 2, 3, 4)}
    for v in (1, 2, 3, 4):
        rep = json.loads((tmp_path / "agents" / "agents" / f"agent-{v}" / "report.json")
                         .read_text())
        edges = rep["extra"]["agent"]["edges"]
        assert len(edges) == 2  # square4: a ring, two neighbours each
        for e in edges.values():
            assert e["received"] > 0 and 0 <= e["age_p50_ms"] < 100.0


def start_agent(team: Path, vid: int, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gcs.cli", "agent", "--team", str(team), "--id", str(vid),
         "--out", str(out / f"agent-{vid}"), "--no-figures", "--mode", "rates"],
        stdout=subprocess.DEVNULL, stderr=open(out / f"agent-{vid}.log", "w"),  # noqa: SIM115
        env={**os.environ, "PYTHONUNBUFFERED": "1"})


def supervisor_time(log: Path) -> float | None:
    """The formation time of the supervisor's latest status line (`t=  12.3s`)."""
    times = [float(line.split("t=")[1].split("s")[0]) for line in
             log.read_text().splitlines() if " t=" in line]
    return times[-1] if times else None


@pytest.mark.alone
def test_an_agent_killed_mid_formation_stops_the_team_on_fresh_data_only(tmp_path):
    # GIVEN four agents, started by hand, flying Scenario I under a supervisor that finds them,
    # their hosts' clocks disciplined (the samples carry the system clock, the echoes check it)
    bind = free_udp_port_block(4)
    team = with_network(team_file(tmp_path, bind, duration_s=40.0, autopilot="px4"),
                        clocks="disciplined")
    # square4's px4 gains at 50 Hz: the cascade criterion's margin 0.399 < 0.4; alpha_p 1.8
    # passes with 0.43
    data = yaml.safe_load(team.read_text())
    data["fly"]["rates"]["alpha_p"] = 1.8
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "team"
    out.mkdir()
    sup_log = tmp_path / "supervisor.log"
    with emulators(team, bind, tmp_path):
        agents = {v: start_agent(team, v, out) for v in (1, 2, 3, 4)}
        sup = subprocess.Popen(
            [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out", str(out),
             "--no-figures", "--agents-running", "--mode", "rates"],
            stdout=subprocess.PIPE, stderr=open(sup_log, "w"), text=True,  # noqa: SIM115
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        try:
            # WHEN the formation has run 10 s, agent 3's process is killed (no goodbye)
            deadline = time.monotonic() + 240.0
            while time.monotonic() < deadline and sup.poll() is None:
                t = supervisor_time(sup_log)
                if t is not None and t >= 10.0:
                    agents[3].send_signal(signal.SIGKILL)
                    break
                time.sleep(0.2)  # polling another process's progress, not synchronising
            assert agents[3].wait(5) is not None, sup_log.read_text()[-3000:]
            # vehicle 3 now gets no setpoints: listen where its agent did, for its modes
            modes = vehicle_modes(team, 3, seconds=6.0)
            stdout, _ = sup.communicate(timeout=200)
        finally:
            for p in (*agents.values(), sup):
                if p.poll() is None:
                    p.terminate()
                    p.wait(30)
    text = sup_log.read_text()
    # THEN the supervisor names the agent that went and the team stops (exit 1); its account
    # is written, and the merged report has the three vehicles whose agents wrote records
    assert sup.returncode == 1, text[-3000:]
    assert "agent of vehicle 3" in text
    account = json.loads((out / "supervisor.json").read_text())
    assert account["outcome"]["exit_code"] == 1
    assert account["agents"]["agent of vehicle 3"]["records"] is None
    merged = json.loads((out / "report.json").read_text())
    assert [v["id"] for v in merged["vehicles"]] == [1, 2, 4]
    # its neighbours saw it stale within the bound and stopped; none flew on data older than
    # fly.stale_after_s (0.1 s); the agent that is no neighbour of 3 stopped on the abort
    for v in (2, 4):
        rep = json.loads((out / f"agent-{v}" / "report.json").read_text())
        agent = rep["extra"]["agent"]
        events = " ".join(e["event"] for e in agent["events"])
        assert "neighbour lost: vehicle 3" in events or "supervisor abort" in events, events
        edge = agent["edges"]["3"]
        assert edge["stale_ticks"] > 0
        assert edge["age_used_max_ms"] <= 100.0
        assert rep["extra"]["outcome"]["exit_code"] == 1
        # the ages came through the system clock, which the echoes found within the tolerance
        # of the agent's (one host: one system clock) and of the supervisor's
        assert agent["clocks"] == "disciplined" and agent["supervisor_offset_s"] == 0.0
        assert abs(agent["supervisor_offset_measured_s"]) <= 0.005, agent
        assert all(abs(e["offset_s"]) <= 0.005 for e in agent["edges"].values()), agent
    rep1 = json.loads((out / "agent-1" / "report.json").read_text())
    assert rep1["extra"]["outcome"]["exit_code"] == 1
    # AND vehicle 3, its agent gone, left OFFBOARD by its own failsafe (PX4: COM_OF_LOSS_T,
    # then COM_OBL_RC_ACT) within seconds, and never flew OFFBOARD again; once landed and
    # disarmed, PX4 puts it back in its intended mode, OFFBOARD, disarmed
    flying_offboard = ("OFFBOARD", True)
    left = next((i for i, state in enumerate(modes) if state != flying_offboard), None)
    assert left is not None, modes
    assert flying_offboard not in modes[left:], modes


def vehicle_modes(team: Path, vid: int, seconds: float) -> list[tuple[str, bool]]:
    """The (flight mode, armed) pairs vehicle `vid` reports in HEARTBEAT for `seconds`, as
    received on its ground-station port (the team file's link.local_port), each change once."""
    data = yaml.safe_load(team.read_text())
    port = next(v["link"]["local_port"] for v in data["vehicles"] if v["id"] == vid)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    modes: list[tuple[str, bool]] = []
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if msg is None or msg.get_srcSystem() != vid:
                continue
            state = (mavutil.mode_string_v10(msg),
                     bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED))
            if not modes or modes[-1] != state:
                modes.append(state)
    finally:
        conn.close()
    return modes
