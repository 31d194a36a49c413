"""One run's row of figures, from its flight log alone: the sweep and `gcs sim --study --run`
call the same function on the same log, so a replay reproduces its row exactly."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gcs import metrics
from gcs.config import TeamConfig
from gcs.config.conditions import conditions
from gcs.control.formation import edge_list
from gcs.control.position import saturated_samples
from gcs.flightlog import FlightLog
from gcs.sweep.study import StudyMetrics

#: The figures of a row after the run's parameters, in column order (docs/sweep.md).
METRICS = (
    "converged", "converge_time_s", "final_error_m", "max_error_m", "mean_error_m",
    "mass_error_pct", "saturation_share", "min_distance_m", "min_force_up_n",
    "conditions_held", "cond.alpha_p", "cond.prop1", "cond.prop2", "cond.uz_positive",
)
BOOLEAN = ("converged", "conditions_held", "cond.alpha_p", "cond.prop1", "cond.prop2",
           "cond.uz_positive")


def failed_row(team: TeamConfig | None) -> dict[str, Any]:
    """The figures of a run that did not finish: NaN, and False where a flight must show it."""
    row: dict[str, Any] = {k: (False if k in BOOLEAN else math.nan) for k in METRICS}
    if team is not None:
        c = conditions(team)
        row.update({"cond.alpha_p": c.alpha_p, "cond.prop1": bool(c.proposition1),
                    "cond.prop2": bool(c.proposition2)})
    return row


def saturation_share(log: FlightLog, team: TeamConfig) -> float:
    """Share of (sample, vehicle) pairs at which a saturated term of the force (23) is past its
    knee: |s_ik| or |v^e_ik| >= sigma_a for some axis k (tanh there is >= 0.76 of its limit)."""
    gains = team.controller.gains
    hits = _saturated(log.t_s, log.position_enu_m, log.velocity_enu_mps, team.adjacency(),
                      log.offsets_enu_m, (gains.c_p, gains.sigma_a),
                      team.reference_velocity.as_arrays())
    return hits / (log.t_s.size * team.n)


def _saturated(t_s: np.ndarray, position_m: np.ndarray, velocity_mps: np.ndarray,
               adjacency: np.ndarray, offsets_m: np.ndarray, gains: tuple[float, float],
               reference: tuple[np.ndarray, ...]) -> int:
    """saturated_samples with every argument in the one type its compiled code takes."""
    def c(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(x, dtype=float)

    return saturated_samples(c(t_s), c(position_m), c(velocity_mps), edge_list(adjacency),
                             c(offsets_m), (float(gains[0]), float(gains[1])),
                             tuple(c(x) for x in reference))


def compile_measure() -> None:
    """Compile the measure's kernel (or load it from numba's cache) before the workers start,
    so they only load it: one vehicle, one sample, its arrays read-only as a log's are."""
    log = [np.zeros(1), np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), np.zeros((1, 3))]
    for x in log:
        x.flags.writeable = False
    t_s, position_m, velocity_mps, offsets_m = log
    _saturated(t_s, position_m, velocity_mps, np.zeros((1, 1)), offsets_m, (1.0, 1.0),
               (np.zeros(3), np.zeros((3, 1)), np.zeros((3, 1)), np.zeros((3, 1))))


def min_distance_m(position_m: np.ndarray) -> float:
    """Least distance between any two vehicles over the log (inf for one vehicle)."""
    n = position_m.shape[1]
    if n < 2:
        return math.inf
    i, j = np.triu_indices(n, 1)
    d = np.linalg.norm(position_m[:, i] - position_m[:, j], axis=-1)
    return float(d.min())


def run_row(log: FlightLog, team: TeamConfig, study: StudyMetrics) -> dict[str, Any]:
    """The figures of a finished run (METRICS, in order)."""
    t = log.t_s
    fe = metrics.formation_error(log.position_enu_m, log.offsets_enu_m)
    settle = metrics.convergence_time(t, fe, study.converged_below_m)
    window = t >= study.window_from_s - 1e-9
    in_window = fe[window] if window.any() else fe[-1:]
    est, true = log.mass_estimate_kg[-1], log.mass_true_kg[-1]
    min_up = float(np.min(log.force_enu_n[..., 2]))
    c = conditions(team)
    row = {
        "converged": settle is not None,
        "converge_time_s": math.nan if settle is None else settle,
        "final_error_m": float(fe[-1]),
        "max_error_m": float(in_window.max()),
        "mean_error_m": float(in_window.mean()),
        "mass_error_pct": float(np.max(np.abs(est - true) / true) * 100.0),
        "saturation_share": saturation_share(log, team),
        "min_distance_m": min_distance_m(log.position_enu_m),
        "min_force_up_n": min_up,
        "cond.alpha_p": c.alpha_p,
        "cond.prop1": bool(c.proposition1),
        "cond.prop2": bool(c.proposition2),
        "cond.uz_positive": min_up > 0.0,
    }
    row["conditions_held"] = all(row[k] for k in ("cond.alpha_p", "cond.prop1", "cond.prop2",
                                                  "cond.uz_positive"))
    return {k: row[k] for k in METRICS}
