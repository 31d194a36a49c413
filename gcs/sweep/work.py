"""What one worker does with a list of run numbers: build each run's team, fly the runs that
share a loop as one batch (gcs.sim.runner.simulate_batch), measure each, return the rows.

A row depends on the study and its run number only, never on which runs shared its batch or
which process flew it (tests/unit/test_sweep.py checks it bit for bit)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from gcs.config import ConfigError, TeamConfig
from gcs.sim.runner import SimOptions, SimulationError, can_batch, simulate_batch
from gcs.sweep.measure import failed_row, run_row
from gcs.sweep.study import Study

STATUS_OK, STATUS_DIVERGED, STATUS_ERROR = "ok", "diverged", "error"


def sim_options(study: Study) -> SimOptions:
    """The options every run of the study flies with (and its replay in gcs sim)."""
    return SimOptions(log_rate_hz=study.metrics.log_rate_hz)


def _row(study: Study, run: int, status: str, message: str, params: dict[str, Any],
         figures: dict[str, Any]) -> dict[str, Any]:
    return {"run": run, "seed": study.run_seed(run), "status": status, "message": message,
            **params, **figures}


def fly_runs(study: Study, runs: Sequence[int]) -> list[dict[str, Any]]:
    """The rows of `runs` (in the order given)."""
    options = sim_options(study)
    rows: dict[int, dict[str, Any]] = {}
    groups: list[list[tuple[int, TeamConfig, dict[str, Any]]]] = []
    for run in runs:
        try:
            team, params = study.team(run)
        except ConfigError as exc:
            rows[run] = _row(study, run, STATUS_ERROR, str(exc), study.draw(run)[1],
                             failed_row(None))
            continue
        for group in groups:
            if can_batch([group[0][1], team], options):
                group.append((run, team, params))
                break
        else:
            groups.append([(run, team, params)])
    for group in groups:
        results = simulate_batch([team for _, team, _ in group], options)
        for (run, team, params), result in zip(group, results, strict=True):
            if isinstance(result, SimulationError):
                rows[run] = _row(study, run, STATUS_DIVERGED, str(result), params,
                                 failed_row(team))
            else:
                rows[run] = _row(study, run, STATUS_OK, "", params,
                                 run_row(result.log, team, study.metrics))
    return [rows[run] for run in runs]
