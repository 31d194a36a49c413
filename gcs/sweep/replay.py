"""`gcs sim --study FILE --run K`: fly one run of a sweep again, with the full records and
figures of gcs sim, and print its row: the same numbers as the sweep's table (the same team from
the same seed, the same options, the same measurement)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from gcs.sim.command import run_one, write_run
from gcs.sim.runner import SimulationError
from gcs.sim.warmup import compile_sim
from gcs.sweep.measure import run_row
from gcs.sweep.study import load_study
from gcs.sweep.work import sim_options

ROW_NAME = "row.json"
#: gcs sim's options that would change the run: a replay takes the study's.
_FIXED = ("controller", "mode", "derivative", "controller_rate_hz", "plant_rate_hz",
          "duration_s")


def run_replay(args: argparse.Namespace) -> int:
    given = [f"--{k.replace('_', '-')}" for k in _FIXED if getattr(args, k) is not None]
    if given:
        print(f"gcs sim: {', '.join(given)}: a replay flies the study's run as the sweep did; "
              "change the study instead", file=sys.stderr)
        return 2
    if args.run is None:
        print("gcs sim: --study needs --run K (the run's number in the sweep's table)",
              file=sys.stderr)
        return 2
    study = load_study(args.study)
    if not 0 <= args.run < study.runs:
        print(f"gcs sim: --run {args.run}: the study has runs 0..{study.runs - 1}",
              file=sys.stderr)
        return 2
    team, params = study.team(args.run)
    out = args.out if args.out is not None else Path("runs") / f"{study.name}-run{args.run}"
    compile_sim(force=False)
    try:
        result = run_one(team, sim_options(study), args.quiet)
    except SimulationError as exc:
        print(f"gcs sim: run {args.run} diverged as in the sweep: {exc}", file=sys.stderr)
        return 1
    write_run(result, team, out, figures=not args.no_figures)
    row = {"run": args.run, "seed": study.run_seed(args.run), **params,
           **run_row(result.log, team, study.metrics)}
    (out / ROW_NAME).write_text(json.dumps(
        {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()},
        indent=2) + "\n")
    width = max(len(k) for k in row)
    for k, v in row.items():
        print(f"  {k:<{width}}  {v}")
    print(f"  records in {out}/ (the row: {out / ROW_NAME})")
    return 0
