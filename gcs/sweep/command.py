"""`gcs sweep`: fly a study's runs on an executor, keep the rows, write the table and analysis."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the CLI builds its parser from here: the compiled parts load on use
    from gcs.sweep.store import ResultStore
    from gcs.sweep.study import Study

EXECUTORS = ("local", "ray")


def add_parser(sub: argparse._SubParsersAction) -> None:
    sweep = sub.add_parser(
        "sweep", help="fly a study's randomized runs of gcs sim and summarize them")
    sweep.add_argument("--study", type=Path, required=True, help="study file (YAML)")
    sweep.add_argument("--out", type=Path, default=None,
                       help="results directory (default runs/sweep-<name>); a rerun resumes")
    sweep.add_argument("--executor", choices=EXECUTORS, default="local",
                       help="local worker processes (default) or a Ray cluster")
    sweep.add_argument("--address", default=None,
                       help="Ray cluster address (default: start a local one)")
    sweep.add_argument("--workers", type=int, default=None,
                       help="local worker processes (default: one per core)")
    sweep.add_argument("--runs", type=int, default=None,
                       help="fly only runs 0..N-1 of the study (default: all)")
    sweep.add_argument("--csv", action="store_true", help="also write runs.csv")
    sweep.add_argument("--quiet", action="store_true", help="no progress output")


def replay_command(study: Study, out: Path) -> str:
    """The command that flies one run again in gcs sim, `{run}` standing for its number."""
    return f"gcs sim --study {study.source} --run {{run}} --out {out}/replay-{{run}}"


def _progress(total: int, quiet: bool) -> tuple[Callable[[int], None], Callable[[], None]]:
    """A progress bar with the time left on a terminal; a line per tenth elsewhere."""
    if quiet:
        return (lambda _: None), (lambda: None)
    if sys.stderr.isatty():
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
        )

        bar = Progress(TextColumn("[bold]sweep"), BarColumn(), MofNCompleteColumn(),
                       TextColumn("runs"), TimeRemainingColumn(), transient=True)
        bar.start()
        task = bar.add_task("sweep", total=total)
        return (lambda n: bar.update(task, completed=n)), bar.stop
    started, shown = time.monotonic(), [0]

    def line(n: int) -> None:
        if n * 10 // max(total, 1) > shown[0] * 10 // max(total, 1) or n == total:
            elapsed = time.monotonic() - started
            left = elapsed / n * (total - n) if n else float("nan")
            print(f"gcs sweep: {n}/{total} runs, {elapsed:.0f} s, about {left:.0f} s left",
                  file=sys.stderr)
        shown[0] = n

    return line, lambda: None


def run_sweep(args: argparse.Namespace) -> int:
    """Entry of `gcs sweep`; returns the exit status (ConfigError is the CLI's to print)."""
    from gcs.sweep.execute import run_local, run_ray
    from gcs.sweep.store import ResultStore, batches
    from gcs.sweep.study import load_study

    study = load_study(args.study)
    total = study.runs if args.runs is None else min(args.runs, study.runs)
    if total < 1 or (args.workers is not None and args.workers < 1):
        print("gcs sweep: --runs and --workers must be >= 1", file=sys.stderr)
        return 2
    out = args.out if args.out is not None else Path("runs") / f"sweep-{study.name}"
    store = ResultStore(out, study)
    done = store.open()
    todo = [r for r in range(total) if r not in done]
    if done and todo:
        print(f"gcs sweep: resuming: {len(done)} runs already in {out}, {len(todo)} to fly",
              file=sys.stderr)
    elif done:
        print(f"gcs sweep: all {total} runs already in {out}; writing the table and analysis",
              file=sys.stderr)
    from gcs.sim.warmup import compile_sim
    from gcs.sweep.measure import compile_measure

    compile_sim(force=False)  # once here, so the workers load the kernels from the cache
    compile_measure()
    update, stop = _progress(total, args.quiet)
    started = time.perf_counter()
    flown = 0
    signalled: list[int] = []
    try:
        with _stopped_by_signals(signalled):
            work = batches(todo, study.batch_runs)
            stream = (run_ray(study, work, args.address) if args.executor == "ray"
                      else run_local(study, work, args.workers))
            count = total - len(todo)
            for rows in stream:
                store.add(rows)
                flown += len(rows)
                count += len(rows)
                update(count)
    except KeyboardInterrupt:
        stop()
        how = signal.Signals(signalled[0]).name if signalled else "SIGINT"
        print(f"gcs sweep: interrupted ({how}) after {flown} runs; the same command resumes",
              file=sys.stderr)
        return 128 + (signalled[0] if signalled else signal.SIGINT)
    except Exception as exc:  # a worker or the cluster failed: what is written stays
        stop()
        print(f"gcs sweep: stopped after {flown} runs: {type(exc).__name__}: {exc}; the "
              "finished batches are kept and the same command resumes", file=sys.stderr)
        return 1
    finally:
        stop()
    wall_s = time.perf_counter() - started
    written = store.finish(args.csv)
    written += _analyse(study, store, out, total)
    table = store.table()
    ok = sum(1 for s in table.column("status").to_pylist() if s == "ok") if table.num_rows else 0
    print(f"gcs sweep: {table.num_rows} runs ({ok} finished, {table.num_rows - ok} diverged or "
          f"refused); flew {flown} in {wall_s:.1f} s wall "
          f"({flown * _run_seconds(study) / max(wall_s, 1e-9):.0f} vehicle-seconds per second)")
    for path in written:
        print(path)
    return 0


@contextlib.contextmanager
def _stopped_by_signals(received: list[int]) -> Iterator[None]:
    """While the runs fly, SIGINT and SIGTERM stop the sweep as Ctrl-C does (the batches written
    stay, the same command resumes), whatever disposition the process started with: a script's
    background job starts with SIGINT ignored, and Python then installs no handler of its own.
    ``received`` collects the signal numbers."""
    def interrupt(signum: int, _frame: object) -> None:
        received.append(signum)
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _run_seconds(study: Study) -> float:
    """Vehicle-seconds of one run (vehicles x simulated seconds of the base team)."""
    return len(study.base["vehicles"]) * float(study.base["mission"]["duration_s"])


def _analyse(study: Study, store: ResultStore, out: Path, total: int) -> list[Path]:
    from gcs.sweep.analysis import AnalysisMeta, write_analysis

    meta = AnalysisMeta(
        study_name=study.name,
        study_file=study.source,
        runs_planned=total,
        replay_template=replay_command(study, out),
        window_start_s=study.metrics.window_from_s,
        converged_below_m=study.metrics.converged_below_m,
        heatmap_pair=(None if study.metrics.heatmap is None
                      else tuple(f"param.{c}" for c in study.metrics.heatmap)),
    )
    return write_analysis(store.table(), meta, out)
