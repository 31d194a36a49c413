"""Actuators mode beside two busy loops: Scenario I (configs/square4.yaml against the nominal
personality) flown N times in actuators mode at 250 Hz, the torque (26) computed on the ground,
while one CPU-bound Python loop per core (nice 0) shares the machine the whole time.

Figures per flight: how it ended (a tilt stop names the vehicle), formation error from t = 30 s
(the paper's 0.05 m), skipped ticks and stalls (>= 50 ms without a tick, which the vehicles fly on
their last torque), telemetry age p99, and the largest inertia estimate against the largest true
inertia of the same vehicle. Writes the "## Actuators mode beside two busy loops" section of
docs/benchmarks.md.

    python -m benchmarks.bench_actuators_busy [--runs 4] [--duration-s 32] [--keep DIR] [--no-write]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.bench_fly import run
from benchmarks.bench_load import busy_processes, case_team
from benchmarks.docsection import publish

ROOT = Path(__file__).resolve().parents[1]

DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## Actuators mode beside two busy loops"


def largest_inertia_estimate(timeseries: Path) -> float:
    """The largest Jhat entry of any vehicle over the flight (the time series' j*_estimate)."""
    head, *rows = (line for line in timeseries.read_text().splitlines()
                   if not line.startswith("#"))
    cols = [head.split(",").index(f"j{a}_estimate_kgm2") for a in "xyz"]
    values = [float(row.split(",")[c]) for row in rows for c in cols if row.split(",")[c]]
    return max(values, default=float("nan"))


def figures(rep: dict, run_dir: Path) -> dict:
    tick, link = rep["tick"], rep["link"].values()
    t = np.asarray(rep["t_s"], dtype=float)
    fe = np.asarray(rep["formation_error_m"], dtype=float)
    late = fe[t >= 30.0]
    gains = rep["extra"]["gains"]
    return {
        "fe_30": float(np.nanmax(late)) if late.size else float("nan"),
        "skipped": tick["skipped_ticks"], "ticks": tick["ticks"], "stalls": tick["stalls"],
        "age_p99": max(v["telemetry_age_p99_ms"] for v in link),
        "jhat_max": largest_inertia_estimate(run_dir / "timeseries.csv"),
        "gains": f"({gains['alpha_eps']:g}, {gains['alpha_omega']:g}), alpha_rho "
                 f"{gains['alpha_rho']:g}",
    }


def section(rows: list[dict], duration_s: float, busy: int) -> str:
    gains = next((r["fig"]["gains"] for r in rows if "fig" in r), "-")
    lines = [
        HEADING, "",
        f"`python -m benchmarks.bench_actuators_busy` on {platform.machine()}, "
        f"{os.cpu_count()} CPU(s), Python {platform.python_version()}: Scenario I in actuators "
        f"mode at 250 Hz, torque gains {gains}, {duration_s:g} s of formation per flight, "
        f"{busy} busy Python loop(s) (nice 0) beside `gcs fly` and one `vehicle-emu --fleet` "
        "(each with its default scheduling). True inertias: 0.0256-0.654 kg m^2.",
        "",
        "| flight | ended | formation error from t = 30 s [m] | skipped ticks | stalls | "
        "telemetry age p99 [ms] | largest Jhat [kg m^2] |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, r in enumerate(rows, 1):
        f = r.get("fig")
        if f is None:
            lines.append(f"| {k} | {r['why'][:140]} | | | | | |")
            continue
        lines.append(f"| {k} | completed | {f['fe_30']:.2e} | {f['skipped']} of {f['ticks']} | "
                     f"{f['stalls']} | {f['age_p99']:.1f} | {f['jhat_max']:.3f} |")
    return "\n".join(lines + [""])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--duration-s", type=float, default=32.0)
    ap.add_argument("--busy", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--keep", type=Path, help="keep each flight's records in this directory")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_actuators_busy_") as scratch:
        tmp = args.keep or Path(scratch)
        for k in range(args.runs):
            work = Path(tmp) / f"run{k}"
            work.mkdir(parents=True)
            row: dict = {}
            with busy_processes(args.busy):
                try:
                    r = run(case_team(work, "square4.yaml", "actuators", "auto"),
                            args.duration_s, work, "actuators", "auto")
                    row["fig"] = figures(r["report"], work / "run")
                except SystemExit as exc:  # gcs fly exited non-zero: its last line says why
                    row["why"] = str(exc).strip().splitlines()[-1]
            rows.append(row)
            print(row, flush=True)
    publish(DOC, HEADING, section(rows, args.duration_s, args.busy), write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
