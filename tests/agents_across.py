"""Scenario I flown by agents across a network (tests/netns.py's testbed): two agent processes,
vehicles 1 and 3 in host 1 and 2 and 4 in host 2, each beside its vehicles' emulator, and the
supervisor in host 3, Zenoh between them over UDP with mixed reliability. Used by
tests/integration/test_agents_netns.py and benchmarks/bench_bus.py ("Flights through it")."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import yaml

from gcs.control.cascade import NOMINAL_RESPONSE
from tests.harness import free_udp_port_block
from tests.netns import Testbed

ROOT = Path(__file__).resolve().parents[1]

PY = sys.executable
#: host -> its agent process's vehicles: on the ring 1-2-3-4-1 every edge crosses the network
HOSTS = {1: (1, 3), 2: (2, 4)}
SUPERVISOR_HOST = 3
#: the agents' tick rate (fly_across says why not 100 Hz)
AGENT_TICK_RATE_HZ = 50
#: Zenoh endpoints of a host's address and port: over TCP, or over UDP with mixed reliability
#: (states as datagrams, control on QUIC streams; docs/agents.md, "The mesh")
ENDPOINTS = {"tcp": lambda host, port: f"tcp/{host}:{port}",
             "udp-mixed": lambda host, port: f"udp/{host}:{port}?rel=1;mixed_rel=1"}


def nominal_team(gcs_base: int, bind_base: int, duration_s: float) -> dict:
    """square4 against the paper's nominal vehicles (as tests/integration/test_fly_emulator.py
    flies them): vehicle i's link on gcs_base + i / bind_base + i."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["mission"]["duration_s"] = duration_s
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_port": bind_base + k}
    data["fly"]["geofence"]["min_enu_m"][2] = 0.5
    data["emulator"] = {"autopilot": "nominal", "origin": "shared"}
    response = dataclasses.asdict(NOMINAL_RESPONSE)
    del response["source"]
    data["fly"]["response"] = response
    data["fly"]["initial_mass"] = "team"
    return data


def fly_across(bed: Testbed, tmp: Path, name: str, transport: str = "udp-mixed",
               clocks: str = "measured") -> dict:
    """Scenario I (45 s, rates, hold at the end) flown by two agent processes, vehicles 1 and 3
    in host 1 and 2 and 4 in host 2, each beside its vehicles, supervised from host 3; returns
    the merged report (per edge figures under extra.edges); FlightFailed if the supervisor
    exits non-zero. `clocks`: network.clocks; disciplined (the hosts' system clocks agree: true
    here, the hosts are namespaces of one kernel) or one-host (their monotonic clocks are one)
    show what the network costs without the clock offsets estimated through it."""
    base = tmp / name
    base.mkdir()
    team = base / "team.yaml"
    data = nominal_team(free_udp_port_block(4), free_udp_port_block(4), duration_s=45.0)
    data["fly"]["end_action"] = "hold"
    # This test measures the network between the agents; the machine's two cores stand for
    # two companion computers, four autopilots and the supervisor's computer. Each agent's own
    # MAVLink link (its vehicles on its host's loopback) then answers 20-45 ms late at times,
    # which preflight rightly judges: the file states that link and flies gains stable at it
    # (the cascade criterion's choice at 50 ms), in both flights alike.
    data["fly"]["link_delay_s"] = 0.05
    # The agents tick at 50 Hz (at 100 Hz each costs more than half a core here, and the
    # machine saturates) with gains the cascade criterion passes there, and run below the
    # vehicles' stand-ins: an agent at SCHED_FIFO (fly.scheduling auto) busy beside the other
    # takes both cores from them for up to the kernel's real-time limit (0.95 s of every
    # second), which their stream rates and TIMESYNC answers then show.
    data["fly"]["rates"].update(k_eps=1.0, k_eps_yaw=2.0, alpha_p=1.5, c_p=2.25,
                                tick_rate_hz=AGENT_TICK_RATE_HZ)
    data["fly"]["scheduling"] = "normal"
    # each host's vehicles in one `vehicle-emu --fleet` (cheaper than a process each)
    data["sim"] = {**data.get("sim", {}), "plant_rate_hz": 500, "controller_rate_hz": 500}

    def endpoint(host: int) -> str:
        return ENDPOINTS[transport](bed.address(host), bed.host(host).free_port(
            "tcp" if transport == "tcp" else "udp"))

    data["network"] = {
        "agents": {v: {"listen": [endpoint(h)]} for h, vs in HOSTS.items() for v in vs},
        "supervisor": {"listen": [endpoint(SUPERVISOR_HOST)]}, "clocks": clocks}
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    procs = []
    # the vehicles first, each ready before the agents start (on two cores, processes
    # loading at once delay every reply by tens of milliseconds, which preflight measures)
    for h, vs in HOSTS.items():
        emu = bed.host(h).popen(
            [PY, "-m", "vehicle_emulator", "--team", host_team(data, vs, base / f"host{h}.yaml"),
             "--fleet", "--log-level", "WARNING"], stdout=subprocess.PIPE, text=True,
            stderr=open(base / f"emu{h}.log", "w"), env=env)  # noqa: SIM115
        procs.append(emu)
        wait_ready_line(emu, "vehicle-emu: ready:", base / f"emu{h}.log")
    for h, vs in HOSTS.items():
        ids = [a for v in vs for a in ("--id", str(v))]
        procs.append(bed.host(h).popen(
            [PY, "-m", "gcs.cli", "agent", "--team", team, *ids, "--mode", "rates",
             "--no-figures", "--out", base / f"agent-{h}"], stdout=subprocess.DEVNULL,
            stderr=open(base / f"agent-{h}.log", "w"), env=env))  # noqa: SIM115
    try:
        sup = bed.host(SUPERVISOR_HOST).run(
            [PY, "-m", "gcs.cli", "fly", "--team", team, "--agents-running", "--mode", "rates",
             "--no-figures", "--out", base / "team"], check=False, capture_output=True,
            text=True, timeout_s=400, env=env)
    finally:
        for p in procs:  # the emulators run until stopped; the agents have ended
            p.terminate()
        for p in procs:
            p.wait(30)
    if sup.returncode != 0:
        raise FlightFailed(sup.returncode, sup.stderr, (
            f"{bed.describe()}\n{sup.stdout}\n{sup.stderr[-3000:]}\n"
            + "\n".join((base / f"agent-{h}.log").read_text()[-1500:] for h in HOSTS)))
    return json.loads((base / "team" / "report.json").read_text())


class FlightFailed(AssertionError):
    """The supervisor exited non-zero: `exit_code`, its `reason` (its last ABORTED line) and,
    as the message, its output and the agents' logs."""

    def __init__(self, exit_code: int, stderr: str, detail: str) -> None:
        super().__init__(detail)
        self.exit_code = exit_code
        lines = [ln for ln in stderr.splitlines() if "ABORTED" in ln or "FAILED" in ln]
        self.reason = lines[-1].strip() if lines else f"exit {exit_code}"


def host_team(data: dict, vehicles: tuple[int, ...], path: Path) -> Path:
    """The team file of one host's emulator: its vehicles only, joined by one edge (a team
    file's graph must be connected; the emulator flies no law)."""
    sub = {**data, "vehicles": [v for v in data["vehicles"] if v["id"] in vehicles],
           "graph": {**data["graph"], "edges": [list(vehicles[:2])]}}
    path.write_text(yaml.safe_dump(sub, sort_keys=False))
    return path


def wait_ready_line(proc: subprocess.Popen, prefix: str, log: Path,
                    timeout_s: float = 60.0) -> None:
    """Return once `proc` printed a line starting with `prefix`; then drain its stdout."""
    done = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            if line.startswith(prefix):
                done.set()

    threading.Thread(target=read, daemon=True).start()
    if not done.wait(timeout_s):
        raise TimeoutError(f"no {prefix!r} within {timeout_s} s: {log.read_text()[-2000:]}")


def error_after(report: dict, t0: float = 30.0) -> np.ndarray:
    t = np.array(report["t_s"])
    return np.array(report["formation_error_m"], dtype=float)[t >= t0]
