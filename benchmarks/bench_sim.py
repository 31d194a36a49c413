"""Benchmark of `gcs sim`: wall time of Scenario I (60 s of flight, 1 kHz plant and law).

Run: `.venv/bin/python -m benchmarks.bench_sim [--repeat 5] [--write docs/benchmarks.md]`.
Measures the first (compiling, or loading numba's cache) run and the median of warm runs, for the
implementable default (model-based derivatives, sampled law), the Levant variant and the
verification mode, and the split between the law and the plant.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from benchmarks.docsection import write_section
from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from gcs.config import load_team  # noqa: E402
from gcs.sim.runner import SimOptions, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

HEADING = "## gcs sim"


def timed(team, options, repeat):
    started = time.perf_counter()
    simulate(team, options)
    first = time.perf_counter() - started
    runs = []
    for _ in range(repeat):
        started = time.perf_counter()
        result = simulate(team, options)
        runs.append(time.perf_counter() - started)
    return first, statistics.median(runs), min(runs), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--write", type=Path, default=None, help="update this markdown file")
    args = parser.parse_args()
    team = load_team(ROOT / "configs" / "square4.yaml")
    cases = [
        ("default: model-based u', u'', law at 1 kHz", SimOptions()),
        ("Levant (28), L = 1e4, 1e-4 s substeps", SimOptions(derivative="levant")),
        ("rates mode (idealised autopilot rate loop)", SimOptions(mode="rates")),
        ("law at 100 Hz (plant still 1 kHz)", SimOptions(mode="rates", controller_rate_hz=100.0)),
        ("verification mode (law in every RK4 stage)", SimOptions(oracle=True)),
    ]
    rows = []
    for label, options in cases:
        first, median, best, result = timed(team, options, args.repeat)
        steps = result.plant_steps
        rows.append((label, first, median, best, 60.0 / median, 1e6 * median / steps))
        print(
            f"{label:48s} first {first:6.2f} s  warm median {median:6.3f} s  best {best:6.3f} s  "
            f"{60.0 / median:6.0f}x real time  {1e6 * median / steps:5.2f} us/step",
            flush=True,
        )
    body = [
        "",
        "Scenario I (`configs/square4.yaml`), 60 s of flight, plant RK4 at 1 kHz, 4 vehicles; "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}. Measured by `python -m benchmarks.bench_sim` "
        f"(median of {args.repeat} warm runs; 'first' includes loading or compiling numba's cache).",
        "",
        "| run | first (s) | warm median (s) | best (s) | x real time | us per plant step |",
        "|---|---|---|---|---|---|",
    ]
    body += [
        f"| {r[0]} | {r[1]:.2f} | {r[2]:.3f} | {r[3]:.3f} | {r[4]:.0f} | {r[5]:.2f} |" for r in rows
    ]
    body += [
        "",
        "Target: 60 s of Scenario I in <= 6 s wall (a plain-numpy reference implementation needs 69 s).",
        "What limits it: the plant RK4 step costs about 1 us for four vehicles (see the 100 Hz row,",
        "where the law runs one step in ten); the rest is the law, evaluated every millisecond. Each",
        "compiled stage allocates its small (n, 3) result arrays, about forty per tick; at roughly",
        "0.1 us each that is an estimated half of a 4-vehicle tick (not profiled further).",
        "What makes it 100x real time and",
        "beyond: compiling the whole closed loop (law + plant) into one numba function per chunk of",
        "one simulated second, so Python is entered 60 times per run instead of 60,000 (done), and",
        "caching the machine code on disk so later runs skip the compile (done). Further headroom,",
        "if ever needed: preallocated work arrays passed into the stages, and running the law at the",
        "rate the vehicle would (100-250 Hz in rates mode), which is already 8x cheaper.",
    ]
    if args.write:
        write_section(args.write, HEADING, HEADING + "\n" + "\n".join(body))
        print(f"updated {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
