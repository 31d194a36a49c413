"""Ticks beside busy processes: `gcs fly` with one CPU-bound process per core running beside it,
under each scheduling policy (`fly.scheduling`, gcs/fly/sched.py).

Each case flies a team (default: configs/grid16.yaml in rates mode at 100 Hz, and Scenario I,
configs/square4.yaml, against the nominal personality in actuators mode at 250 Hz) against one
`vehicle-emu --fleet`, while `os.cpu_count()` busy Python loops (normally scheduled, nice 0)
share the machine from before the flight to its end. The case's policy is both the ground
station's `fly.scheduling` and the fleet's `--scheduling` (each asks for its own priority; the
fleet one step below). Figures per case: ticks on time, lateness p99, skipped ticks, telemetry
age p99 (worst vehicle), formation error at the end, and the scheduling each got. Writes the "## Ticks
beside busy processes" section of docs/benchmarks.md.

    python -m benchmarks.bench_load [--duration-s 30] [--policies normal auto] [--no-write]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import yaml

from benchmarks.bench_fly import run
from benchmarks.docsection import publish

ROOT = Path(__file__).resolve().parents[1]

DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## Ticks beside busy processes"
BUSY = "while True:\n    pass\n"


@contextlib.contextmanager
def busy_processes(n: int) -> Iterator[None]:
    """n CPU-bound Python processes, stopped on exit."""
    procs = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def case_team(work: Path, name: str, mode: str, policy: str) -> Path:
    """The bundled team file with the case's mode and scheduling (and, for square4, the
    nominal personality whose actuator setpoints the 250 Hz torque law flies)."""
    data = yaml.safe_load((ROOT / "configs" / name).read_text())
    data["controller"]["mode"] = mode
    data.setdefault("fly", {})["scheduling"] = policy
    if name == "square4.yaml":
        data["emulator"] = {"autopilot": "nominal", "origin": "shared"}
        data["fly"]["initial_mass"] = "team"
    path = work / f"{Path(name).stem}-{mode}-{policy}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def figures(r: dict) -> dict:
    rep = r["report"]
    tick, link = rep["tick"], rep["link"].values()
    return {
        "on_time": 100.0 - tick["late_pct"], "ticks": tick["ticks"],
        "late_p99": tick["lateness_p99_ms"], "skipped": tick["skipped_ticks"],
        "age_p99": max(v["telemetry_age_p99_ms"] for v in link),
        "fe_end": rep["summary"]["final_formation_error_m"],
        "scheduling": tick.get("scheduling", "-"),
        "emu_scheduling": r["emu"].get("scheduling", "-"),
        "gcs_cpu": 100 * r["gcs_cpu_s"] / r["gcs_wall_s"],
    }


def section(rows: list[dict], duration_s: float, busy: int) -> str:
    lines = [
        HEADING, "",
        f"`python -m benchmarks.bench_load` on {platform.machine()}, {os.cpu_count()} CPU(s), "
        f"Python {platform.python_version()}: {busy} busy Python loop(s) (one per core, nice 0) "
        f"running beside `gcs fly` and one `vehicle-emu --fleet`, {duration_s:g} s of formation "
        "per case. The policy is the ground station's `fly.scheduling` (gcs/fly/sched.py; "
        "docs/gcs.md, \"Scheduling\") and the fleet's `--scheduling` (docs/emulator.md, "
        "\"Scheduling\"); what each got is in the last two columns.",
        "",
        "| team, mode | fly.scheduling | ticks on time | lateness p99 [ms] | skipped | telemetry "
        "age p99 [ms] | formation error at the end [m] | GCS CPU | ground station got | fleet got |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        f = r.get("fig")
        head = f"| {r['team']}, {r['mode']} | {r['policy']} |"
        if f is None:
            lines.append(f"{head} failed: {r['why'][:120]} | | | | | | | |")
            continue
        lines.append(f"{head} {f['on_time']:.2f} % of {f['ticks']} | {f['late_p99']:.2f} | "
                     f"{f['skipped']} | {f['age_p99']:.1f} | {f['fe_end']:.2e} | "
                     f"{f['gcs_cpu']:.0f} % | {f['scheduling']} | {f['emu_scheduling']} |")
    lines += ["", "A tick is on time when it starts within max(1.5 ms, a fifth of its period) "
              "of its absolute deadline (docs/architecture.md, \"The tick\").", ""]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=30.0)
    ap.add_argument("--policies", nargs="+", default=["normal", "auto"])
    ap.add_argument("--busy", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    cases = [("grid16.yaml", "rates"), ("square4.yaml", "actuators")]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_load_") as tmp:
        for name, mode in cases:
            for policy in args.policies:
                work = Path(tmp) / f"{name}-{mode}-{policy}"
                work.mkdir()
                row = {"team": name.removesuffix(".yaml"), "mode": mode, "policy": policy}
                rows.append(row)
                with busy_processes(args.busy):
                    try:
                        row["fig"] = figures(run(case_team(work, name, mode, policy),
                                                 args.duration_s, work, mode, policy))
                    except SystemExit as exc:  # gcs fly exited non-zero
                        row["why"] = str(exc).strip().splitlines()[-1]
                print(row, flush=True)
    text = section(rows, args.duration_s, args.busy)
    publish(DOC, HEADING, text, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
