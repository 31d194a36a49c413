"""`gcs sim` and `gcs plot`: run the simulation(s), write the records, print the summary."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from gcs.config import TeamConfig, load_team
from gcs.flightlog import FlightLog
from gcs.flightlog_csv import load_timeseries, save_timeseries
from gcs.plots import write_comparison_figures, write_figures
from gcs.report import build_report, summary_table, write_report
from gcs.sim.runner import SimOptions, SimResult, SimulationError, simulate
from gcs.sim.warmup import compile_sim

REPORT_NAME = "report.json"
TIMESERIES_NAME = "timeseries.csv"


def _progress_printer(
    label: str, quiet: bool
) -> tuple[Callable[[float, float], None] | None, Callable[[], None]]:
    """A rich progress bar on a terminal, nothing otherwise (logs stay clean in CI)."""
    if quiet or not sys.stderr.isatty():
        return None, lambda: None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
        TimeRemainingColumn(),
        transient=True,
    )
    bar.start()
    task = bar.add_task(label, total=1.0)

    def update(t_s: float, duration_s: float) -> None:
        bar.update(task, completed=t_s, total=duration_s)

    return update, bar.stop


def write_run(result: SimResult, team: TeamConfig, out_dir: Path, figures: bool) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    log = result.log
    write_report(out_dir / REPORT_NAME, build_report(log))
    save_timeseries(log, out_dir / TIMESERIES_NAME)
    if figures:
        edges = [(e.i, e.j) for e in team.graph.edges]
        write_figures(log, out_dir, pairs=edges)


def run_one(team: TeamConfig, options: SimOptions, quiet: bool) -> SimResult:
    update, stop = _progress_printer(f"sim {team.name} ({options.law})", quiet)
    try:
        return simulate(team, options, update)
    finally:
        stop()


def run_sim(args: argparse.Namespace) -> int:
    """Entry of `gcs sim`; returns the process exit status."""
    team = load_team(args.team)
    laws = (
        ["adaptive", "baseline"]
        if args.controller == "both"
        else [args.controller or team.controller.law]
    )
    out = args.out if args.out is not None else Path("runs") / team.name
    ignored = [f for f in team.faults if getattr(f, "kind", "") != "mass_drop"]
    for fault in ignored:
        print(
            f"gcs sim: note: fault {fault.kind!r} on vehicle {fault.vehicle} acts on the MAVLink "
            "link or the emulator; the in-process simulation does not apply it",
            file=sys.stderr,
        )
    compile_sim(force=False)  # announced on a cold cache, then loaded like any run
    logs: dict[str, FlightLog] = {}
    for law in laws:
        options = SimOptions(
            law=law,
            mode=args.mode,
            derivative=args.derivative,
            controller_rate_hz=args.controller_rate_hz,
            plant_rate_hz=args.plant_rate_hz,
            duration_s=args.duration_s,
        )
        try:
            result = run_one(team, options, args.quiet)
        except SimulationError as exc:
            print(f"gcs sim: {law}: {exc}", file=sys.stderr)
            return 1
        run_dir = out / law if len(laws) > 1 else out
        write_run(result, team, run_dir, figures=not args.no_figures)
        logs[law] = result.log
        print(summary_table(result.log))
        print(
            f"  simulated {result.plant_steps / (result.log.extra['plant_rate_hz']):.0f} s in "
            f"{result.wall_s:.2f} s wall; records in {run_dir}/"
        )
        print()
    if len(laws) > 1 and not args.no_figures:
        paths = write_comparison_figures(logs["adaptive"], logs["baseline"], out)
        print("comparison figures: " + ", ".join(str(p) for p in paths))
    return 0


def run_plot(run_dir: Path, out: Path | None) -> int:
    """Entry of `gcs plot`: redraw a run's figures from its time series (and compare if the
    directory holds adaptive/ and baseline/ runs)."""
    target = out or run_dir
    single = run_dir / TIMESERIES_NAME
    pair = (run_dir / "adaptive" / TIMESERIES_NAME, run_dir / "baseline" / TIMESERIES_NAME)
    written: list[Path] = []
    if single.is_file():
        written += write_figures(load_timeseries(single), target)
    elif all(p.is_file() for p in pair):
        adaptive, baseline = (load_timeseries(p) for p in pair)
        written += write_figures(adaptive, target / "adaptive")
        written += write_figures(baseline, target / "baseline")
        written += write_comparison_figures(adaptive, baseline, target)
    else:
        print(
            f"gcs plot: {run_dir} holds no {TIMESERIES_NAME} (nor adaptive/ and baseline/ runs)",
            file=sys.stderr,
        )
        return 2
    for path in written:
        print(path)
    return 0
