"""The flight report (report.json, docs/report.md) and the terminal summary of a FlightLog.

``build_report`` resamples the log every ``REPORT_PERIOD_S`` (0.1 s) by picking the samples at
multiples of 0.1 s, converts positions and velocities from the app's ENU to local NED
(p_ned = (y, x, -z), gcs.frames.ned_from_enu), and writes ``null`` wherever a value is unknown
(NaN in the log, or no log sample at a grid time). Fields beyond the schema: ``name``,
``log_period_s``, per-vehicle ``offset_ned_m``, ``summary`` (figures from the full-rate log, see
``run_summary``) and ``extra`` (the log's extra figures other than link and tick).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gcs import metrics
from gcs.flightlog import FlightLog
from gcs.frames import ned_from_enu

SCHEMA = "formation-flight-report/1"
REPORT_PERIOD_S = 0.1
#: Times [s] at which the summary reports the formation error (those within the run).
CHECKPOINTS_S = (5.0, 10.0, 20.0, 30.0, 60.0)
#: Formation error [m] below which a simulated formation counts as converged (summary only).
CONVERGED_FORMATION_ERROR_M = 0.01
#: A flown formation (source "fly") is judged against the smallest of these it stays below over
#: at least the last FLY_CONVERGED_HOLD_FRACTION of the run: flown vehicles hold decimetres
#: (estimator noise, link delay), not the simulation's 0.01 m, which they never meet, and a
#: noisy error that dips below a threshold in the last few samples has not converged to it.
#: Samples whose error is unknown (a skipped tick) are left out.
FLY_CONVERGED_FORMATION_ERRORS_M = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
FLY_CONVERGED_HOLD_FRACTION = 1 / 3
LINK_FIELDS = (
    "setpoints_sent",
    "telemetry_received",
    "telemetry_lost_pct",
    "telemetry_age_p50_ms",
    "telemetry_age_p99_ms",
)
TICK_FIELDS = ("rate_hz", "late_pct", "lateness_p99_ms")


def _nullable(a: np.ndarray) -> Any:
    """numpy array -> nested lists of Python floats, NaN/inf -> None."""
    arr = np.asarray(a, dtype=np.float64)
    obj = arr.astype(object)
    obj[~np.isfinite(arr)] = None
    return obj.tolist()


def _optional(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def run_summary(log: FlightLog) -> dict[str, Any]:
    """Key figures of a run from the full-rate log (JSON-ready; None where unknown).

    formation_error_m_at: {"5.0": e, ...} at the CHECKPOINTS_S within the run (nearest sample);
    final_*: at the last sample; formation_converged_t_s: first time after which the formation
    error stays below formation_converged_below_m (None if it does not), which is
    CONVERGED_FORMATION_ERROR_M for a simulation and, for a flight, the smallest of
    FLY_CONVERGED_FORMATION_ERRORS_M that the error stays below over the last third of the run
    (the largest, with None, if none); per vehicle (in
    vehicle_ids order): mass estimate and truth at 10 s (if within the run) and at the end, peak
    thrust, min u_z (force_enu_n z: must stay > 0 for the law to be defined), max attitude error
    and max |omega^e|.
    """
    t = log.t_s
    t_end = float(t[-1])
    fe = metrics.formation_error(log.position_enu_m, log.offsets_enu_m)
    ve = metrics.velocity_error(log.velocity_enu_mps, log.reference_velocity_enu_mps)
    at = {
        f"{c:g}": _optional(metrics.value_at(t, fe, c))
        for c in CHECKPOINTS_S
        if t[0] <= c <= t_end + 1e-9
    }

    def per_vehicle(a: np.ndarray | float) -> list[float | None]:
        return [_optional(x) for x in np.asarray(a, dtype=np.float64).tolist()]

    has_10 = t[0] <= 10.0 <= t_end + 1e-9
    converged_below_m, converged_t_s = _converged(log.source, t, fe)
    return {
        "t_end_s": t_end,
        "formation_error_m_at": at,
        "final_formation_error_m": _optional(float(fe[-1])),
        "final_velocity_error_mps": _optional(float(ve[-1])),
        "formation_converged_below_m": converged_below_m,
        "formation_converged_t_s": converged_t_s,
        "max_attitude_error": _optional(metrics.max_over_window(t, log.attitude_error.max(axis=1))),
        "vehicles": {
            "id": log.vehicle_ids.tolist(),
            "mass_estimate_kg_at_10s": (
                per_vehicle(metrics.value_at(t, log.mass_estimate_kg, 10.0)) if has_10 else None
            ),
            "mass_true_kg_at_10s": (
                per_vehicle(metrics.value_at(t, log.mass_true_kg, 10.0)) if has_10 else None
            ),
            "final_mass_estimate_kg": per_vehicle(log.mass_estimate_kg[-1]),
            "final_mass_true_kg": per_vehicle(log.mass_true_kg[-1]),
            "peak_thrust_n": per_vehicle(metrics.max_over_window(t, log.thrust_n)),
            "min_force_up_n": per_vehicle(metrics.min_over_window(t, log.force_enu_n[..., 2])),
            "max_attitude_error": per_vehicle(metrics.max_over_window(t, log.attitude_error)),
            "max_omega_error_radps": per_vehicle(metrics.max_over_window(t, log.omega_error_radps)),
        },
    }


def _converged(source: str, t_s: np.ndarray, error_m: np.ndarray) -> tuple[float, float | None]:
    """(threshold [m], time from which the formation error stays below it, or None): see
    run_summary."""
    if source != "fly":
        return CONVERGED_FORMATION_ERROR_M, metrics.convergence_time(
            t_s, error_m, CONVERGED_FORMATION_ERROR_M)
    known = np.isfinite(error_m)
    if known.any():
        t_known, e_known = t_s[known], error_m[known]
        latest_s = t_s[-1] - FLY_CONVERGED_HOLD_FRACTION * (t_s[-1] - t_s[0])
        for threshold in FLY_CONVERGED_FORMATION_ERRORS_M:
            t = metrics.convergence_time(t_known, e_known, threshold)
            if t is not None and t <= latest_s:
                return threshold, t
    return FLY_CONVERGED_FORMATION_ERRORS_M[-1], None


def _check_stats(what: str, stats: Mapping[str, Any], fields: tuple[str, ...]) -> dict[str, Any]:
    missing = [f for f in fields if f not in stats]
    if missing:
        raise ValueError(f"report {what}: missing fields {missing} (docs/report.md)")
    return dict(stats)


def build_report(
    log: FlightLog,
    link: Mapping[Any, Mapping[str, Any]] | None = None,
    tick: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The report.json dict of ``log`` (schema formation-flight-report/1), JSON-ready, no NaN.

    ``link``: per vehicle id (int or str keys) the fields of LINK_FIELDS; ``tick``: TICK_FIELDS.
    Both are for ``fly``; when not passed they are taken from ``log.extra["link"/"tick"]`` if
    present, and left out of the report otherwise. Raises ValueError for a ``fly`` log without
    them, for a link entry missing a vehicle, or for a missing field.
    """
    link = link if link is not None else log.extra.get("link")
    tick = tick if tick is not None else log.extra.get("tick")
    if log.source == "fly" and (link is None or tick is None):
        raise ValueError(
            "report of a 'fly' log: the link and tick statistics are mandatory "
            "(docs/report.md); pass link= and tick="
        )

    grid_t, idx = metrics.grid_indices(log.t_s, REPORT_PERIOD_S)
    gap = idx < 0
    take = np.where(gap, 0, idx)

    def sample(a: np.ndarray) -> np.ndarray:
        out = np.array(a[take], dtype=np.float64)
        out[gap] = np.nan
        return out

    position = sample(log.position_enu_m)
    velocity = sample(log.velocity_enu_mps)
    reference = sample(log.reference_velocity_enu_mps)
    attitude = sample(log.attitude_error)
    mass_true_t0 = log.mass_true_kg[
        metrics.nearest_index(log.t_s, 0.0) if log.t_s[0] <= 0.0 <= log.t_s[-1] else 0
    ]
    offsets_ned = ned_from_enu(log.offsets_enu_m)

    report: dict[str, Any] = {
        "schema": SCHEMA,
        "source": log.source,
        "controller": log.controller,
        "team": log.team,
        "name": log.name,
        "vehicles": [
            {
                "id": int(vid),
                "sysid": int(sid),
                "mass_true_kg": _optional(float(m)),
                "offset_ned_m": [float(x) for x in off],
            }
            for vid, sid, m, off in zip(
                log.vehicle_ids, log.sysids, mass_true_t0, offsets_ned, strict=True
            )
        ],
        "log_period_s": _optional(log.period_s),
        "t_s": [float(x) for x in grid_t],
        "formation_error_m": _nullable(metrics.formation_error(position, log.offsets_enu_m)),
        "velocity_error_mps": _nullable(metrics.velocity_error(velocity, reference)),
        "attitude_error": _nullable(attitude.max(axis=1)),
        "mass_estimate_kg": _nullable(sample(log.mass_estimate_kg)),
        "mass_true_kg": _nullable(sample(log.mass_true_kg)),
        "position_ned_m": _nullable(ned_from_enu(position)),
        "velocity_ned_mps": _nullable(ned_from_enu(velocity)),
        "thrust_n": _nullable(sample(log.thrust_n)),
        "summary": run_summary(log),
    }
    if link is not None:
        entries = {str(k): v for k, v in link.items()}
        absent = [int(v) for v in log.vehicle_ids if str(int(v)) not in entries]
        if absent:
            raise ValueError(f"report link: no statistics for vehicles {absent}")
        report["link"] = {
            key: _check_stats(f"link[{key!r}]", stats, LINK_FIELDS)
            for key, stats in entries.items()
        }
    if tick is not None:
        report["tick"] = _check_stats("tick", tick, TICK_FIELDS)
    extra = {k: v for k, v in log.extra.items() if k not in ("link", "tick")}
    if extra:
        report["extra"] = extra
    return _sanitize(report)


def _sanitize(obj: Any) -> Any:
    """Recursively: numpy -> Python, NaN/inf -> None, tuples -> lists, keys -> str."""
    if isinstance(obj, Mapping):
        return {str(k): _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return _sanitize(obj.tolist())
    if isinstance(obj, list | tuple):
        return [_sanitize(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    raise TypeError(f"report: value of type {type(obj).__name__} is not JSON-compatible: {obj!r}")


def write_report(path: str | os.PathLike[str], report: Mapping[str, Any]) -> Path:
    """Write ``report`` as JSON (NaN and +-inf become null; never NaN/Infinity tokens).

    One top-level field per line, each value compact, so the file reads in a pager and diffs well.
    Written to a temporary name and renamed, so a reader never sees half a file. Returns the path
    once written.
    """
    path = Path(path)
    clean = _sanitize(report)
    body = ",\n".join(
        f" {json.dumps(key)}: {json.dumps(value, allow_nan=False, separators=(', ', ': '))}"
        for key, value in clean.items()
    )
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("{\n" + body + "\n}\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


# --------------------------------------------------------------------------------------------------
# Terminal summary


def _fmt(x: float | None, spec: str = ".3g") -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, spec)


def summary_table(log: FlightLog) -> str:
    """A short plain-text table of the run's key figures (see run_summary), for the terminal."""
    s = run_summary(log)
    v = s["vehicles"]
    lines = [
        f"run {log.name!r}: {log.source}, {log.controller}, team {log.team}, "
        f"{log.n_vehicles} vehicles, t = {log.t_s[0]:g}..{s['t_end_s']:g} s",
    ]
    rows: list[tuple[str, str]] = [
        (f"formation error at t = {t} s [m]", _fmt(e)) for t, e in s["formation_error_m_at"].items()
    ]
    rows += [
        (f"formation error at end ({s['t_end_s']:g} s) [m]", _fmt(s["final_formation_error_m"])),
        ("velocity error at end [m/s]", _fmt(s["final_velocity_error_mps"])),
        (
            f"formation error stays < {s['formation_converged_below_m']:g} m from t [s]",
            _fmt(s["formation_converged_t_s"], ".2f"),
        ),
        ("max attitude error tr(I-R^e)", _fmt(s["max_attitude_error"])),
    ]
    width = max(len(r[0]) for r in rows)
    lines += [f"  {label:<{width}}  {value}" for label, value in rows]

    has_10 = v["mass_estimate_kg_at_10s"] is not None
    header = ["UAV"]
    if has_10:
        header += ["m_est@10s[kg]", "m_true@10s"]
    header += ["m_est@end[kg]", "m_true@end", "peak T[N]", "min u_z[N]", "max tr(I-Re)"]
    table = [header]
    for j, vid in enumerate(v["id"]):
        row = [str(vid)]
        if has_10:
            row += [
                _fmt(v["mass_estimate_kg_at_10s"][j], ".4f"),
                _fmt(v["mass_true_kg_at_10s"][j], ".4f"),
            ]
        row += [
            _fmt(v["final_mass_estimate_kg"][j], ".4f"),
            _fmt(v["final_mass_true_kg"][j], ".4f"),
            _fmt(v["peak_thrust_n"][j], ".2f"),
            _fmt(v["min_force_up_n"][j], ".2f"),
            _fmt(v["max_attitude_error"][j], ".3g"),
        ]
        table.append(row)
    widths = [max(len(r[c]) for r in table) for c in range(len(header))]
    lines.append("")
    lines += [
        "  " + "  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)) for r in table
    ]
    return "\n".join(lines)
