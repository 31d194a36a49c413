"""Scale benchmark of `gcs fly`: grids of 4 to 240 vehicles (benchmarks/make_grid.py, one shared
GCS port), rates mode at 100 Hz, each flown against one `vehicle-emu --fleet` process (nominal
personality, streams only as asked) on this machine; beside each, `gcs sim` of the same team and
gains. Writes the "## Scale" section of docs/benchmarks.md and docs/figures/bench_scale.png.

    python -m benchmarks.bench_scale [--sizes 4,16,36,64,100,144,240] [--duration-s 60]
                                     [--no-sim] [--no-write]

Figures per size: ticks on time (started <= 2 ms after the deadline), tick lateness p99, the
telemetry's true age p99 (largest over the vehicles), the CPU of the ground station and of the
emulator per vehicle (% of one core, over the whole run), the formation error (largest over all
pairs) at the end, and gcs sim's at the same time. How fast the machine was: the share of its
CPU time the hypervisor took (steal, /proc/stat) during each flight, and, before and after the
sweep, `benchmarks/bench_edges.py`'s 240-vehicle tick (median and best over 2 s), the figure the
notes compare between days.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.bench_edges import time_grid  # noqa: E402
from benchmarks.docsection import write_section  # noqa: E402
from benchmarks.fleet import fleet  # noqa: E402
from benchmarks.fleet import fly as gcs_fly  # noqa: E402
from benchmarks.make_grid import team_text  # noqa: E402
from gcs.control.position import phi  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
FIGURE = ROOT / "docs" / "figures" / "bench_scale.png"
HEADING = "## Scale"
SHARED_PORT = 14550

GRIDS = {4: (2, 2), 16: (4, 4), 36: (6, 6), 64: (8, 8), 100: (10, 10), 144: (12, 12),
         240: (15, 16)}


def team_files(n: int, duration_s: float, work: Path) -> tuple[Path, Path]:
    """The flight's team file and gcs sim's (the fly.rates gains as controller gains, and the
    initial mass estimate the hover gives a flight: phi(0) m / alpha_m)."""
    rows, cols = GRIDS[n]
    data = yaml.safe_load(team_text(rows, cols, SHARED_PORT))
    data["mission"]["duration_s"] = duration_s
    data["emulator"] = {"autopilot": "nominal", "origin": "shared"}
    fly_path = work / f"grid{n}.yaml"
    fly_path.write_text(yaml.safe_dump(data, sort_keys=False))
    gains = data["controller"]["gains"]
    rates = data["fly"]["rates"]
    gains.update({k: rates[k] for k in ("alpha_p", "c_p", "k_eps", "k_eps_yaw") if k in rates})
    phi0 = float(phi(np.zeros((1, 3)), gains["sigma_a"])[0])
    for v in data["vehicles"]:
        v["estimates"]["mhat"] = phi0 * v["plant"]["mass_kg"] / gains["alpha_m"]
    sim_path = work / f"grid{n}_sim.yaml"
    sim_path.write_text(yaml.safe_dump(data, sort_keys=False))
    return fly_path, sim_path


def cpu_times() -> list[int]:
    """The machine's CPU times from /proc/stat (user nice system idle iowait irq softirq steal
    ..., in clock ticks); empty where there is no /proc/stat."""
    try:
        with open("/proc/stat") as f:
            return [int(x) for x in f.readline().split()[1:]]
    except (OSError, ValueError):
        return []


def steal_pct(before: list[int], after: list[int]) -> float:
    """% of all CPU time between two `cpu_times` that the hypervisor took (steal, field 8)."""
    if len(before) < 8 or len(after) < 8:
        return float("nan")
    total = sum(after[:8]) - sum(before[:8])
    return 100.0 * (after[7] - before[7]) / total if total > 0 else float("nan")


def reference_tick() -> tuple[float, float]:
    """`benchmarks/bench_edges.py`'s 240-vehicle tick on this machine now: (median, best) [us]
    over 2 s of back-to-back ticks."""
    rows, cols = GRIDS[240]
    row = time_grid(240, rows, cols, 2.0)
    return row["tick_median_us"], row["tick_best_us"]


def fly(team: Path, work: Path) -> dict:
    emu_stats = work / "emu.json"
    with fleet(team, "--streams", "requested", "--stats-json", str(emu_stats)):
        cpu0 = cpu_times()
        flight = gcs_fly(team, work / "fly", "--mode", "rates", "--end-action", "hold",
                          merged=True, timeout_s=3600.0)
        steal = steal_pct(cpu0, cpu_times())
    emu_figures = json.loads(emu_stats.read_text()) if emu_stats.exists() else {}
    last = (flight.stdout.strip().splitlines() or [""])[-1]
    return {"exit": flight.exit, "why": last, "report": flight.report, "emu": emu_figures,
            "gcs_cpu_s": flight.cpu_s, "gcs_wall_s": flight.wall_s, "steal": steal}


def sim(team: Path, work: Path) -> dict | None:
    out = work / "sim"
    proc = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--team", str(team),
                           "--mode", "rates", "--out", str(out), "--no-figures"],
                          capture_output=True, text=True, timeout=3600)
    report = out / "report.json"
    return json.loads(report.read_text()) if proc.returncode == 0 and report.exists() else None


def end_error(report: dict | None) -> float:
    if report is None:
        return float("nan")
    return float(report["summary"]["final_formation_error_m"])


def figures(n: int, r: dict, sim_report: dict | None) -> dict:
    rep = r["report"]
    row: dict = {"n": n, "exit": r["exit"], "why": r["why"], "sim_end_m": end_error(sim_report),
                 "steal_pct": r["steal"]}
    emu = r["emu"]
    emu_cpu = emu.get("cpu_s")
    emu_wall = emu.get("wall_s") or emu.get("simulated_s")
    row["emu_cpu_pct_per_vehicle"] = (100.0 * emu_cpu / emu_wall / n
                                      if emu_cpu is not None and emu_wall else float("nan"))
    row["gcs_cpu_pct_per_vehicle"] = 100.0 * r["gcs_cpu_s"] / r["gcs_wall_s"] / n
    if rep is None:
        row.update(on_time=float("nan"), late_p99=float("nan"), age_p99=float("nan"),
                   end_m=float("nan"), t_end=float("nan"))
        return row
    tick = rep["tick"]
    link = rep["link"].values()
    row.update(on_time=100.0 - tick["late_pct"], late_p99=tick["lateness_p99_ms"],
               age_p99=max(v["telemetry_age_p99_ms"] for v in link),
               end_m=end_error(rep), t_end=rep["summary"]["t_end_s"])
    return row


def _f(x: float, fmt: str = ".3g") -> str:
    return "-" if x != x else format(x, fmt)


def _first_reason(why: str) -> str:
    """The exit line up to its first per-vehicle note, and how many there were (240 vehicles'
    'link lost while stopping' do not belong in a table's footnote)."""
    head, sep, rest = why.partition("; vehicle ")
    if not sep:
        return why
    return f"{head}; and {rest.count('; vehicle ') + 1} per-vehicle notes"


def section(rows: list[dict], duration_s: float, ticks: list[tuple[float, float]]) -> str:
    lines = [
        HEADING, "",
        f"`python -m benchmarks.bench_scale` on {platform.machine()}, {os.cpu_count()} CPU(s), "
        f"Python {platform.python_version()}: grids from `benchmarks/make_grid.py` "
        "(configs/grid240.yaml is the 15 x 16 one) behind one shared GCS port, rates mode at "
        f"100 Hz, {duration_s:g} s of formation, against one `vehicle-emu --fleet --streams "
        "requested` (nominal personality) on the same machine. On time: the tick started <= 2 ms "
        "after its deadline. Age: the telemetry's true age (from the vehicle's own stamps) p99, "
        "the largest over the vehicles. CPU: % of one core per vehicle over the whole run "
        "(start-up, preflight, formation). Error: the largest over all pairs at the end; `sim`: "
        "`gcs sim` of the same team and gains (no link). Steal: % of the machine's CPU time the "
        "hypervisor took during the flight. The machine's speed: `benchmarks/bench_edges.py`'s "
        "240-vehicle tick took " + " and ".join(
            f"{median:.0f} us (best {best:.0f})" for median, best in ticks)
        + " before and after the sweep.", "",
        "| vehicles | exit | ticks on time | lateness p99 [ms] | age p99 [ms] | GCS CPU / vehicle "
        "| emulator CPU / vehicle | error at end [m] | sim [m] | steal |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['exit']} | {_f(r['on_time'], '.2f')} % | {_f(r['late_p99'])} | "
            f"{_f(r['age_p99'])} | {_f(r['gcs_cpu_pct_per_vehicle'], '.2f')} % | "
            f"{_f(r['emu_cpu_pct_per_vehicle'], '.2f')} % | {_f(r['end_m'])} | "
            f"{_f(r['sim_end_m'])} | {_f(r['steal_pct'], '.1f')} % |")
    failed = [r for r in rows if r["exit"] != 0]
    if failed:
        lines += ["", "Exits other than 0: " + "; ".join(
            f"{r['n']} vehicles: `{_first_reason(r['why'])}`" for r in failed)]
    lines += ["", "![scale](figures/bench_scale.png)", ""]
    return "\n".join(lines)


def plot(rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["n"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    axes[0].plot(n, [r["on_time"] for r in rows], "o-")
    axes[0].axhline(99.0, color="k", ls=":", lw=0.8)
    axes[0].set(xlabel="vehicles", ylabel="ticks on time [%]")
    axes[1].plot(n, [r["gcs_cpu_pct_per_vehicle"] for r in rows], "o-", label="ground station")
    axes[1].plot(n, [r["emu_cpu_pct_per_vehicle"] for r in rows], "s-", label="emulator")
    axes[1].set(xlabel="vehicles", ylabel="CPU per vehicle [% of a core]")
    axes[1].legend()
    axes[2].semilogy(n, [r["end_m"] for r in rows], "o-", label="gcs fly")
    axes[2].semilogy(n, [r["sim_end_m"] for r in rows], "kx:", label="gcs sim")
    axes[2].set(xlabel="vehicles", ylabel="formation error at the end [m]")
    axes[2].legend()
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE, dpi=110)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="4,16,36,64,100,144,240")
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--no-sim", action="store_true")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    rows, ticks = [], [reference_tick()]
    for n in (int(x) for x in args.sizes.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            fly_team, sim_team = team_files(n, args.duration_s, work)
            r = fly(fly_team, work)
            sim_report = None if args.no_sim else sim(sim_team, work)
            row = figures(n, r, sim_report)
        rows.append(row)
        print(json.dumps(row), flush=True)
    ticks.append(reference_tick())
    text = section(rows, args.duration_s, ticks)
    print(text)
    if not args.no_write:
        plot(rows)
        write_section(DOC, HEADING, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
