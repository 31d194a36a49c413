"""Agents per vehicle (`gcs fly --agents`): what one costs, and whether the team flies as the
central ground station does (docs/benchmarks.md, "Agents").

    python -m benchmarks.bench_agents [--part sizing|accuracy|all] [--flights K] [--no-write]

sizing: grid16 as 16 agents in 4 processes (`--agents-per-process 4`) against one
`vehicle-emu --fleet`, 30 s of formation; from each agent's records its processor time, wall time
and bus traffic, per vehicle; with the supervisor, the processor time of the whole team of
processes. accuracy: Scenario I (square4, rates, 60 s) on the nominal and px4 personalities, K
flights of `gcs fly` and K of `gcs fly --agents` each, each against a fresh fleet, the law at
`ACCURACY_TICK_RATE_HZ` with gains the cascade criterion passes there: formation error for
t >= 30 s and the mass estimates at 20 s. Every flight is the command a user types, on free
ports of 127.0.0.1. A part not run keeps its subsection of the doc as it was.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from benchmarks.docsection import publish
from tests.harness import free_udp_port_block

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## Agents (`gcs fly --agents`)"
#: grid16's four agent processes and its sixteen emulated vehicles share two cores here; each
#: agent stands for a companion computer of its own and each vehicle for an autopilot with a
#: processor of its own. Agents above the fleet (the vehicles' stand-in, nice -5) would starve
#: it whenever they are busy together (its TIMESYNC answers then come 0.3 s late and the flight
#: stops, as it should): here the agents run normally scheduled, below the vehicles.
SIZING_SCHEDULING = "normal"
#: the fleet's sixteen vehicles as the paper's model: the px4 personality's sixteen estimators
#: and inner loops beside four agent processes saturate the two cores (its TIMESYNC answers
#: then come 0.3 s late and the flight stops, as it should)
SIZING_AUTOPILOT = "nominal"
PY = sys.executable
#: The accuracy flights' law rate: four agents at 100 Hz cost about 1.4 of this machine's two
#: cores beside the fleet, and 35-39 % of their ticks are late (docs/agents.md); at 50 Hz they
#: fit, as in tests/integration/test_agents.py.
ACCURACY_TICK_RATE_HZ = 50
#: fly.rates at that rate: the cascade criterion's proposal there on PX4 and ArduPilot defaults
#: (the shipped 100 Hz gains leave a modulus margin of 0.40 at 50 Hz, short of its bound)
ACCURACY_GAINS = {"k_eps": 1.0, "k_eps_yaw": 1.0, "alpha_p": 1.5, "c_p": 1.6875}


def on_free_ports(src: Path, dst: Path, duration_s: float, autopilot: str | None = None,
                  end_action: str | None = None, scheduling: str | None = None) -> Path:
    """`src` with every vehicle's link and the bus on free ports, the formation `duration_s`."""
    data = yaml.safe_load(src.read_text())
    n = len(data["vehicles"])
    gcs_base, emu_base = free_udp_port_block(n), free_udp_port_block(n)
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_port": emu_base + k}
    data["mission"]["duration_s"] = duration_s
    data["network"] = {"base_port": free_udp_port_block(n + 2, kind=socket.SOCK_STREAM)}
    if autopilot is not None:
        data.setdefault("emulator", {})["autopilot"] = autopilot
    if end_action is not None:
        data["fly"]["end_action"] = end_action
    if scheduling is not None:
        data["fly"]["scheduling"] = scheduling
        # four agent processes, the supervisor and sixteen vehicles normally scheduled on two
        # cores: a process may wait a second for its turn, which the liveness bounds allow;
        # and the agents tick at 50 Hz (at 100 Hz the four need ~1.8 cores beside the fleet)
        data["network"].update(stale_after_s=3.0, supervisor_lost_after_s=3.0)
        data["fly"]["rates"]["tick_rate_hz"] = 50
    dst.write_text(yaml.safe_dump(data, sort_keys=False))
    return dst


def fly(team: Path, out: Path, *args: str) -> tuple[int, float, str]:
    """`vehicle-emu --fleet` and `gcs fly ARGS`: exit status, processor time of gcs fly and
    everything it started and waited for [s], and its stderr's tail."""
    emu = subprocess.Popen([PY, "-m", "vehicle_emulator", "--team", str(team), "--fleet",
                            "--log-level", "WARNING"], stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        proc = subprocess.run([PY, "-m", "gcs.cli", "fly", "--team", str(team), "--out",
                               str(out), "--no-figures", "--mode", "rates", *args],
                              capture_output=True, text=True, timeout=900,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        emu.terminate()
        emu.wait(30)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return proc.returncode, cpu, proc.stderr[-2000:]


def sizing(tmp: Path) -> str:
    team = on_free_ports(ROOT / "configs" / "grid16.yaml", tmp / "grid16.yaml", 30.0,
                         SIZING_AUTOPILOT, end_action="hold", scheduling=SIZING_SCHEDULING)
    out = tmp / "grid16"
    t0 = time.monotonic()
    code, cpu_all, err = fly(team, out, "--agents", "--agents-per-process", "4")
    wall = time.monotonic() - t0
    if code != 0:
        raise SystemExit(f"grid16 as agents: exit {code}\n{err}")
    rows = []
    for d in sorted((out / "agents").iterdir()):
        if not d.is_dir():
            continue
        a = json.loads((d / "report.json").read_text())["extra"]["agent"]
        k = len(a["vehicles"])
        tr = a["bus_traffic"]
        rows.append((a["vehicles"], a["cpu_s"], a["wall_s"], k, tr))
    report = json.loads((out / "report.json").read_text())
    t = np.array(report["t_s"])
    e = np.array(report["formation_error_m"], dtype=float)
    cpu_pct = [100.0 * c / w / k for _, c, w, k, _ in rows]
    sent = [tr["sent_bytes"] / w / k for _, _, w, k, tr in rows]
    got = [tr["received_bytes"] / w / k for _, _, w, k, tr in rows]
    msgs = [tr["sent"] / w / k for _, _, w, k, tr in rows]
    lines = [
        "grid16 (16 vehicles, rates at 50 Hz) as 16 agents in 4 processes "
        "(`gcs fly --agents --agents-per-process 4`, fly.scheduling normal, the network's liveness bounds 3 s) against one "
        "`vehicle-emu --fleet` (nominal personality), 30 s "
        "of formation, 127.0.0.1, 2-core machine; each agent process's own records "
        "(processor time over its whole life: start, connect, preflight, formation, stop):",
        "",
        "| agent process (vehicles) | CPU per vehicle [% of one core] | bus sent per vehicle "
        "[kB/s, messages/s] | bus received per vehicle [kB/s] |",
        "|---|---|---|---|",
    ]
    for (vids, *_), p, s, g, m in zip(rows, cpu_pct, sent, got, msgs, strict=True):
        lines.append(f"| {', '.join(map(str, vids))} | {p:.1f} | {s / 1e3:.1f}, {m:.0f} | "
                     f"{g / 1e3:.1f} |")
    lines += [
        "",
        f"Per vehicle: CPU {np.mean(cpu_pct):.1f} % of a core (mean over processes), bus "
        f"{np.mean(sent) / 1e3:.1f} kB/s sent and {np.mean(got) / 1e3:.1f} kB/s received (state "
        "samples at the tick rate to each subscriber, statuses at 5 Hz, the supervisor's "
        "heartbeats). The supervisor and the four agent processes together used "
        f"{cpu_all:.0f} s of processor time in {wall:.0f} s wall ({100 * cpu_all / wall:.0f} % "
        "of one core, including start-up). The team flew: formation error "
        f"{np.nanmean(e[t >= 20.0]):.4f} m mean, {np.nanmax(e[t >= 20.0]):.4f} m max for "
        "t >= 20 s.",
    ]
    return "\n".join(lines)


def accuracy(tmp: Path, flights: int) -> str:
    lines = [
        f"Scenario I (square4, rates, 60 s formation, land) against `vehicle-emu --fleet`, "
        f"{flights} flights each of `gcs fly` (central) and `gcs fly --agents` (4 agent "
        f"processes), a fresh fleet each, the law at {ACCURACY_TICK_RATE_HZ} Hz with "
        + ", ".join(f"{k} {v:g}" for k, v in ACCURACY_GAINS.items())
        + " (at 100 Hz the four agents beside the fleet saturate this machine's two cores), the "
        "agents scheduled as `gcs fly --agents` starts them (here normally: docs/agents.md): "
        "formation error for t >= 30 s (mean / max, each flight) and the mass estimates at "
        "t = 20 s (mean over flights).",
        "",
        "| personality | how | formation error t >= 30 s, mean / max [m] | mass at 20 s [kg] |",
        "|---|---|---|---|",
    ]
    verdicts = []
    for autopilot in ("nominal", "px4"):
        figures: dict[str, list[tuple[float, float, np.ndarray]]] = {}
        for how, args in (("central", ()), ("agents", ("--agents",))):
            for k in range(flights):
                team = on_free_ports(ROOT / "configs" / "square4.yaml",
                                     tmp / f"{autopilot}-{how}-{k}.yaml", 60.0, autopilot)
                data = yaml.safe_load(team.read_text())
                data["fly"]["rates"].update(ACCURACY_GAINS, tick_rate_hz=ACCURACY_TICK_RATE_HZ)
                team.write_text(yaml.safe_dump(data, sort_keys=False))
                out = tmp / f"{autopilot}-{how}-{k}"
                code, _, err = fly(team, out, *args)
                if code != 0:
                    raise SystemExit(f"{autopilot} {how} flight {k}: exit {code}\n{err}")
                r = json.loads((out / "report.json").read_text())
                t = np.array(r["t_s"])
                e = np.array(r["formation_error_m"], dtype=float)[t >= 30.0]
                mass = np.array(r["mass_estimate_kg"], dtype=float)
                rows = np.flatnonzero(np.isfinite(mass).all(axis=1))
                m20 = mass[rows[np.argmin(np.abs(t[rows] - 20.0))]]
                figures.setdefault(how, []).append((float(np.nanmean(e)),
                                                    float(np.nanmax(e)), m20))
        for how, runs in figures.items():
            errs = ", ".join(f"{a:.4f} / {b:.4f}" for a, b, _ in runs)
            mass = np.mean([m for _, _, m in runs], axis=0)
            lines.append(f"| {autopilot} | {how} | {errs} | "
                         f"{', '.join(f'{x:.3f}' for x in mass)} |")
        c_mean = np.mean([a for a, _, _ in figures["central"]])
        a_mean = np.mean([a for a, _, _ in figures["agents"]])
        c_max = np.mean([b for _, b, _ in figures["central"]])
        a_max = np.mean([b for _, b, _ in figures["agents"]])
        c_m = np.mean([m for _, _, m in figures["central"]], axis=0)
        a_m = np.mean([m for _, _, m in figures["agents"]], axis=0)
        spread = max(b for _, b, _ in figures["central"]) / min(
            b for _, b, _ in figures["central"])
        verdicts.append(
            f"{autopilot}: agents / central, mean {a_mean / c_mean:.2f}, max {a_max / c_max:.2f} "
            f"(absolute {abs(a_mean - c_mean) * 1e3:.1f} / {abs(a_max - c_max) * 1e3:.1f} mm); "
            f"masses within {100 * np.max(np.abs(a_m / c_m - 1)):.1f} %; the central flights' "
            f"own max spread {spread:.2f}x")
    return "\n".join([*lines, "", *(f"* {v}" for v in verdicts)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("sizing", "accuracy", "all"), default="all")
    ap.add_argument("--flights", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    doc = ROOT / "docs" / "benchmarks.md"
    with tempfile.TemporaryDirectory(prefix="bench-agents-") as d:
        tmp = Path(d)
        parts = []
        for part, title, run in (
                ("sizing", "### What an agent costs", lambda: sizing(tmp)),
                ("accuracy", "### Agents against the central ground station",
                 lambda: accuracy(tmp, args.flights))):
            body = run() if args.part in (part, "all") else kept_subsection(doc, title)
            if body:
                parts.append(f"{title}\n\n{body}")
    text = (f"{HEADING}\n\n`python -m benchmarks.bench_agents` ({time.strftime('%Y-%m-%d')}, "
            f"this 2-core machine).\n\n" + "\n\n".join(parts) + "\n")
    publish(doc, HEADING, text, write=not args.no_write)


def kept_subsection(doc: Path, title: str) -> str:
    """The body of `title`'s subsection of HEADING's section in `doc` ("" if none)."""
    text = doc.read_text() if doc.exists() else ""
    start = text.find(HEADING + "\n")
    if start < 0:
        return ""
    end = text.find("\n## ", start + len(HEADING))
    section = text[start:] if end < 0 else text[start:end]
    at = section.find(title + "\n")
    if at < 0:
        return ""
    body = section[at + len(title):]
    nxt = body.find("\n### ")
    return (body if nxt < 0 else body[:nxt]).strip("\n")


if __name__ == "__main__":
    main()
