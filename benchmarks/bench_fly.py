"""Benchmark of `gcs fly`: the 16-vehicle grid (configs/grid16.yaml) in rates mode at 100 Hz
against one `vehicle-emu --fleet` process on this machine; writes the "## gcs fly" section of
docs/benchmarks.md (tick timing, telemetry age, formation error, CPU of the GCS and the emulator).

    python -m benchmarks.bench_fly [--team configs/grid16.yaml] [--duration-s 60] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
from pathlib import Path

from benchmarks.docsection import write_section
from benchmarks.fleet import fleet, fly

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## gcs fly"


def run(team: Path, duration_s: float, work: Path, mode: str = "rates",
        emu_scheduling: str = "auto") -> dict:
    """One flight of ``team`` against a fleet started with ``--scheduling emu_scheduling``;
    SystemExit (with gcs fly's output) if gcs fly exits non-zero."""
    emu_stats = work / "emu.json"
    with fleet(team, "--stats-json", str(emu_stats), "--scheduling", emu_scheduling):
        flight = fly(team, work / "run", "--mode", mode, "--duration-s", str(duration_s),
                     "--end-action", "hold", merged=True)
        if flight.exit != 0:
            raise SystemExit(f"gcs fly exited {flight.exit}:\n{flight.stdout}")
    if flight.report is None:
        raise SystemExit(f"gcs fly wrote no {flight.out / 'report.json'}:\n{flight.stdout}")
    emu_figures = json.loads(emu_stats.read_text())  # written when the fleet stopped
    return {"report": flight.report, "gcs_cpu_s": flight.cpu_s, "gcs_wall_s": flight.wall_s,
            "gcs_rss_mb": flight.rss_mb, "emu": emu_figures}


def section(r: dict, team: Path, duration_s: float) -> str:
    rep, tick, emu = r["report"], r["report"]["tick"], r["emu"]
    link = rep["link"].values()
    age50 = max(v["telemetry_age_p50_ms"] for v in link)
    age99 = max(v["telemetry_age_p99_ms"] for v in link)
    lost = max(v["telemetry_lost_pct"] for v in link)
    stale = sum(v["stale_own_ticks"] + v["stale_neighbour_ticks"] for v in link)
    summary = rep["summary"]
    on_time = 100.0 - tick["late_pct"]
    lines = [
        HEADING,
        "",
        f"`python -m benchmarks.bench_fly` on {platform.machine()}, {os.cpu_count()} CPU(s), "
        f"Python {platform.python_version()}: `{team.relative_to(ROOT)}` "
        f"({len(rep['vehicles'])} vehicles), rates mode at {tick['rate_hz']:g} Hz, "
        f"{duration_s:g} s of formation, one `vehicle-emu --fleet` process on the same machine.",
        "",
        "| figure | value |",
        "|---|---|",
        f"| ticks on time (start <= {tick['late_threshold_ms']:.1f} ms after the deadline) | "
        f"**{on_time:.2f} %** of {tick['ticks']} |",
        f"| tick lateness p50 / p99 / max | {tick['lateness_p50_ms']:.2f} / "
        f"{tick['lateness_p99_ms']:.2f} / {tick['lateness_max_ms']:.2f} ms |",
        f"| skipped ticks | {tick['skipped_ticks']} |",
        f"| scheduling the ground station got (fly.scheduling) | {tick.get('scheduling', '-')} |",
        f"| tick compute (snapshot + law for the team + 16 setpoints) p50 / p99 | "
        f"{tick['compute_p50_ms']:.2f} / {tick['compute_p99_ms']:.2f} ms |",
        f"| telemetry age used by the law, worst vehicle p50 / p99 | {age50:.1f} / "
        f"{age99:.1f} ms |",
        f"| telemetry lost, worst vehicle | {lost:.2f} % |",
        f"| stale samples (own + neighbour, all vehicles) | {stale} |",
        f"| formation error at t = 30 s / at the end | "
        f"{summary['formation_error_m_at'].get('30', float('nan')):.2e} / "
        f"{summary['final_formation_error_m']:.2e} m |",
        f"| GCS CPU (whole run incl. start-up) | {r['gcs_cpu_s']:.1f} s in {r['gcs_wall_s']:.1f} s "
        f"wall = {100 * r['gcs_cpu_s'] / r['gcs_wall_s']:.0f} % of one core, max RSS "
        f"{r['gcs_rss_mb']:.0f} MB |",
        f"| emulator CPU | {emu['cpu_s']:.1f} s in {emu['wall_s']:.1f} s = "
        f"{100 * emu['cpu_fraction']:.0f} % of one core; its tick lateness mean "
        f"{emu['late_mean_ms']:.2f} ms, p99 {emu['late_p99_ms']:.2f} ms |",
        "",
        "The emulator flies its default personality (px4): the formation error is the noise "
        "floor of its PX4-like position estimates, the largest over the team's pairs (docs/gcs.md, "
        "\"Did the vehicles follow?\"; bench_personalities.py), not the law's accuracy. "
        "The acceptance asks >= 99 % of ticks on time. Lateness is measured from the tick's "
        "absolute deadline t0 + k h (the loop never sleeps a relative period, so it does not "
        "drift); a tick more than a period late is skipped and counted, never run twice.",
        "",
    ]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--team", type=Path, default=ROOT / "configs" / "grid16.yaml")
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--no-write", action="store_true", help="print, do not edit the doc")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        result = run(args.team.resolve(), args.duration_s, Path(tmp))
    text = section(result, args.team.resolve(), args.duration_s)
    print(text)
    if not args.no_write:
        write_section(DOC, HEADING, text)
        print(f"wrote the '{HEADING}' section of {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
