"""`gcs sweep` on the shipped studies: wall time and throughput (docs/benchmarks.md, "gcs
sweep"), and each study's summary and figures (docs/sweep.md, "The shipped studies").

    python -m benchmarks.bench_sweep [--executor local|ray] [--no-write]

Each study is swept from an empty out directory by the command a user types (`gcs sweep --study
FILE --out DIR --quiet`), timed from start to exit (start-up, kernels from the cache, the runs,
the table and the analysis). Beside it, one Scenario I run of the first study alone in this
process, and the same run inside a batch of 32, per run: what batching saves.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

import numpy as np  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

from benchmarks.docsection import publish  # noqa: E402
from gcs.sim.runner import simulate, simulate_batch  # noqa: E402
from gcs.sweep.analysis import (  # noqa: E402
    bin_parameter,
    binned_rate,
    param_columns,
    ran,
    successes,
)
from gcs.sweep.plots import success_filename  # noqa: E402
from gcs.sweep.study import load_study  # noqa: E402
from gcs.sweep.work import sim_options  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ("configs/study_scenario1.yaml", "configs/study_link.yaml")
SPEED_HEADING = "## gcs sweep"
STUDIES_HEADING = "## The shipped studies"
FIGURES = ROOT / "docs" / "figures" / "sweep"


def sweep(study: str, out: Path, executor: str) -> float:
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "gcs.cli", "sweep", "--study", study, "--out",
                           str(out), "--quiet", "--executor", executor], cwd=ROOT,
                          capture_output=True, text=True)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"gcs sweep --study {study} failed:\n{done.stderr}")
    return wall


def per_run_ms(study_path: str) -> tuple[float, float]:
    """One run alone and the same runs in one batch of 32, ms per run (best of 3)."""
    study = load_study(ROOT / study_path)
    teams = [study.team(k)[0] for k in range(32)]
    options = sim_options(study)
    simulate(teams[0], options)
    alone = min(_timed(lambda: [simulate(t, options) for t in teams[:8]]) / 8 for _ in range(3))
    batch = min(_timed(lambda: simulate_batch(teams, options)) / 32 for _ in range(3))
    return alone * 1e3, batch * 1e3


#: What the same team flew on the px4 personality and on real PX4 SIH, from the ground, per
#: (fly.velocity_from_position_s, fly.acceleration_from_velocity_s) (docs/benchmarks.md, "Real
#: PX4 SIH and the px4 personality"; docs/gcs.md, "The law's velocity"): formation error for
#: t >= 30 s, mean / max [m]. The first row's flights flew the file as it is (phi_horizontal 0,
#: the velocity correction bounded at 1.5 m/s): SIH runs 8-10 and the personality beside them.
PX4_RECORDED = {
    (0.2, 0.5): "personality 0.077 / 0.122, 0.082 / 0.158; real SIH (six flights) "
                "0.078-0.112 / 0.134-0.200, median 0.095 / 0.169",
    (0.0, 0.0): "personality (Scenario I from 10 m, before its heading error followed the time "
                "since takeoff, before the acceleration's correction) 0.267 / 0.415, "
                "0.329 / 0.525",
}


#: The ArduCopter SITL team file (tests/data/sitl/team_arducopter_sitl.yaml) with the rates gains
#: the 2026-12-04 SITL flight flew (its report.json: alpha_p 1, c_p 2, k_eps 1.5, k_eps_yaw 1)
ARDUPILOT_TEAM = "tests/data/sitl/team_arducopter_sitl.yaml"
ARDUPILOT_FLOWN_GAINS = {"alpha_p": 1.0, "c_p": 2.0, "k_eps": 1.5, "k_eps_yaw": 1.0}
#: What that file flew over MAVLink (fly.velocity_from_position_s 0.2, the default): the
#: ardupilot personality (`vehicle-emu --fleet --team FILE --autopilot ardupilot --param
#: GUID_OPTIONS=8`, then `gcs fly --team FILE`, one fleet per flight) and real ArduCopter SITL
#: (flights/2026-12-04/ardupilot_rates_1st): formation error for t >= 30 s, mean / max [m].
ARDUPILOT_RECORDED = ("personality 0.0028 / 0.0080, 0.0037 / 0.0088, 0.0039 / 0.0094 (to 55 s); "
                      "real ArduCopter SITL 0.0040 / 0.0217")


def _late_error(data: dict) -> str:
    """gcs sim on the team `data`; its formation error for t >= 30 s, mean / max [m]."""
    from gcs.config import team_from_dict
    from gcs.metrics import formation_error
    from gcs.sim.runner import SimOptions

    log = simulate(team_from_dict(data), SimOptions(log_rate_hz=50)).log
    e = formation_error(log.position_enu_m, log.offsets_enu_m)[log.t_s >= 30]
    return f"{e.mean():.{3 if e.mean() >= 0.01 else 4}f} / {e.max():.{3 if e.max() >= 0.01 else 4}f}"


def autopilot_comparison(seeds: tuple[int, ...] = (1, 2, 3)) -> list[str]:
    """gcs sim on sim.autopilot px4 (configs/square4_px4sih.yaml's rates gains; its loops, drag
    and telemetry errors, 4 ms of link), with the velocity and acceleration corrections as each
    recorded flight flew them, and on ardupilot (the ArduCopter SITL team file as flown), beside
    the recordings."""
    import copy

    from gcs.config import load_team, team_to_dict

    rows = ["| sim.autopilot | fly.velocity_from_position_s | fly.acceleration_from_velocity_s "
            f"| gcs sim, seeds {', '.join(map(str, seeds))}: mean / max [m] | flown |",
            "|---|---|---|---|---|"]
    base = team_to_dict(load_team(ROOT / "configs" / "square4_px4sih.yaml"))
    for t_s, t_a in PX4_RECORDED:
        figures = []
        for seed in seeds:
            data = copy.deepcopy(base)
            data["controller"]["mode"] = "rates"
            rates = data["fly"]["rates"]
            data["controller"]["gains"].update(
                {k: rates[k] for k in ("alpha_p", "c_p", "k_eps", "k_eps_yaw")})
            # as the flights it is compared with read the velocity and the acceleration
            data["fly"]["velocity_from_position_s"] = t_s
            data["fly"]["acceleration_from_velocity_s"] = t_a
            data["sim"].update(controller_rate_hz=100, autopilot="px4", link_seed=seed,
                               link_delay_s=0.004)
            figures.append(_late_error(data))
        rows.append(f"| px4 | {t_s:g} s | {t_a:g} s | {', '.join(figures)} | "
                    f"{PX4_RECORDED[t_s, t_a]} |")
    base = team_to_dict(load_team(ROOT / ARDUPILOT_TEAM))
    figures = []
    for seed in seeds:
        data = copy.deepcopy(base)
        data["controller"]["mode"] = "rates"
        data["controller"]["gains"].update(ARDUPILOT_FLOWN_GAINS)
        data["fly"]["acceleration_from_velocity_s"] = 0.0
        data["sim"].update(plant_rate_hz=1000, controller_rate_hz=100, autopilot="ardupilot",
                           link_seed=seed, link_delay_s=0.004)
        figures.append(_late_error(data))
    velocity_s = base["fly"].get("velocity_from_position_s", 0.2)
    rows.append(f"| ardupilot | {velocity_s:g} s | 0 s | {', '.join(figures)} | "
                f"{ARDUPILOT_RECORDED} |")
    return rows


def _timed(work) -> float:
    started = time.perf_counter()
    work()
    return time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--executor", default="local", choices=("local", "ray"))
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    rows, sections = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for study_path in STUDIES:
            study = load_study(ROOT / study_path)
            out = Path(tmp) / study.name
            wall = sweep(study_path, out, args.executor)
            summary = json.loads((out / "summary.json").read_text())
            vehicle_s = study.runs * len(study.base["vehicles"]) * \
                float(study.base["mission"]["duration_s"])
            rows.append((study_path, study.runs, wall, vehicle_s / wall, summary))
            sections.append(_study_section(study_path, study.name, out, summary))
    alone_ms, batch_ms = per_run_ms(STUDIES[0])
    cores = os.cpu_count()
    lines = [
        SPEED_HEADING, "",
        f"`benchmarks/bench_sweep.py` (rerun: `.venv/bin/python -m benchmarks.bench_sweep`). "
        f"Each shipped study swept from an empty out directory by `gcs sweep --study FILE --out "
        f"DIR --quiet --executor {args.executor}` on this {cores}-core machine, timed from start "
        "to exit (start-up, the runs, the table, the analysis and its figures). "
        "Vehicle-seconds: runs x vehicles x simulated seconds.", "",
        "| study | runs | wall [s] | vehicle-seconds per wall second | ok / diverged / error |",
        "|---|---|---|---|---|",
    ]
    for path, runs, wall, rate, summary in rows:
        status = summary["status"]
        lines.append(f"| `{path}` | {runs} | {wall:.1f} | {rate:,.0f} | "
                     f"{status.get('ok', 0)} / {status.get('diverged', 0)} / "
                     f"{status.get('error', 0)} |")
    lines += ["", f"Per run, Scenario I of `{STUDIES[0]}` in this process on one core: "
              f"{alone_ms:.1f} ms alone, {batch_ms:.1f} ms inside a batch of 32 (best of 3).",
              "", "`gcs sim` on PX4's and ArduPilot's loops, airframes and telemetry errors "
              "(`sim.autopilot`, docs/sweep.md: px4's drag and the law's acceleration from the "
              "accelerometer and the reported attitude, with the corrections as the flights "
              "beside it flew them; ardupilot's position estimate error and the records gcs fly "
              "holds a stream period) against what the same gains flew over "
              "MAVLink, formation error for t >= 30 s, Scenario I at 100 Hz (the sim starts at "
              "the initial positions, the flights from the ground or from 10 m, as noted):", "",
              *autopilot_comparison()]
    publish(ROOT / "docs" / "benchmarks.md", SPEED_HEADING, "\n".join(lines) + "\n",
            not args.no_write)
    publish(ROOT / "docs" / "sweep.md", STUDIES_HEADING,
            "\n".join([STUDIES_HEADING, "", "Produced by `.venv/bin/python -m "
                       "benchmarks.bench_sweep` (each study swept as above; its summary and "
                       "figures copied here).", ""] + sections) + "\n", not args.no_write)
    return 0


def strongest(out: Path, count: int) -> list[str]:
    """The `count` parameters along which the success rate moves most (largest spread of the
    binned rate): the success figures worth a reader's look."""
    table = pq.read_table(out / "runs.parquet")
    success, counted = successes(table), ran(table)
    spread = {}
    for column in param_columns(table):
        rate = binned_rate(bin_parameter(table, column), success, counted).rate
        if np.isfinite(rate).sum() > 1:
            spread[column] = float(np.nanmax(rate) - np.nanmin(rate))
    return sorted(spread, key=lambda c: -spread[c])[:count]


def _study_section(study_path: str, name: str, out: Path, summary: dict) -> str:
    """The study's summary (headings one level down) and its ECDF, heat map and the success
    figures of the parameters that matter most, copied under docs/figures/sweep/<name>/."""
    target = FIGURES / name
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    figures = [out / success_filename(c) for c in strongest(out, 4)]
    figures += [out / "ecdf_converge_time.png", out / "heatmap.png"]
    for png in figures:
        shutil.copy(png, target / png.name)
    lines = (out / "summary.md").read_text().strip().splitlines()
    body = "\n".join(("###" + line) if line.startswith("#") else line for line in lines[1:])
    links = "\n".join(f"![{p.stem}](figures/sweep/{name}/{p.name})" for p in figures)
    return (f"### `{study_path}`\n\n`gcs sweep --study {study_path}` "
            f"({summary['runs_done']} runs)\n{body}\n\n{links}\n")


if __name__ == "__main__":
    sys.exit(main())
