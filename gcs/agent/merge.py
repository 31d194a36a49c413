"""One report of a team flown by agents: each agent's records (report.json, timeseries.csv in
its own directory) merged into the records `gcs fly` writes for a whole team (pure but for the
files it reads and writes).

Every agent logs its formation time t from the agreed formation start (its own clock's image
of the supervisor's instant), every 1 / fly.log_rate_hz from its first law tick; the agents'
ticks are not in phase. The merged log interpolates each agent's series linearly to the log
grid (multiples of the log period) over the span every agent logged, the vehicles in team-file
order; the team's figures (formation error, velocity error) are computed
over all of them as for a `gcs fly` flight. The link of each vehicle is its agent's; the tick
figures are the worst agent's (its late ticks), each agent's under `extra.agents`; every edge's
neighbour figures (age at use, loss, clock offset) under `extra.edges` as "i<-j" (an agent of
vehicles i and k: "i+k<-j").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gcs.flightlog import SERIES_SHAPES, FlightLog
from gcs.flightlog_csv import load_timeseries, save_timeseries
from gcs.fly.records import REPORT_NAME, TIMESERIES_NAME
from gcs.report import build_report, write_report

__all__ = ["MergeError", "merge_logs", "merge_records"]

#: series of FlightLog that are per team, not per vehicle
_TEAM_SERIES = ("t_s", "reference_velocity_enu_mps")


class MergeError(ValueError):
    """The agents' records cannot be merged; one line."""


def _at(t_s: np.ndarray, series: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """`series` (k, ...) sampled at `t_s`, linearly interpolated at `grid`."""
    flat = series.reshape(series.shape[0], -1)
    out = np.empty((grid.size, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(grid, t_s, flat[:, c])
    return out.reshape(grid.size, *series.shape[1:])


def merge_logs(logs: Sequence[FlightLog], order: Sequence[int], name: str,
               agents: dict[str, Any]) -> FlightLog:
    """The team's log from its agents' logs: every series interpolated to the log grid over
    the span all agents logged, the vehicles in `order` (team ids)."""
    if not logs:
        raise MergeError("no agent wrote a formation log")
    spaced = [log.period_s for log in logs if log.n_samples > 1]
    if not spaced:
        raise MergeError("the agents' logs hold one sample each: nothing to merge")
    period = min(spaced)
    first = max(float(log.t_s[0]) for log in logs)
    last = min(float(log.t_s[-1]) for log in logs)
    grid = np.arange(math.ceil(first / period - 1e-9), math.floor(last / period + 1e-9) + 1
                     ) * period
    if grid.size == 0:
        raise MergeError(f"the agents' logs share no time span (latest start {first:.3f} s, "
                         f"earliest end {last:.3f} s): did they agree on the formation start?")
    where: dict[int, tuple[int, int]] = {}
    for a, log in enumerate(logs):
        for j, vid in enumerate(log.vehicle_ids.tolist()):
            if vid in where:
                raise MergeError(f"vehicle {vid} is in the logs of two agents")
            where[vid] = (a, j)
    missing = [vid for vid in order if vid not in where]
    if missing:
        raise MergeError(f"no agent's log has vehicles {missing}")
    cache: dict[tuple[int, str], np.ndarray] = {}

    def per_vehicle(field: str) -> np.ndarray:
        cols = []
        for v in order:
            a, j = where[v]
            if (a, field) not in cache:
                cache[(a, field)] = _at(logs[a].t_s, getattr(logs[a], field), grid)
            cols.append(cache[(a, field)][:, j])
        return np.stack(cols, axis=1)

    lead = logs[0]
    series = {f: per_vehicle(f) for f in SERIES_SHAPES if f not in _TEAM_SERIES}
    extra: dict[str, Any] = {"agents": agents}
    link: dict[str, Any] = {}
    for log in logs:
        link.update(log.extra.get("link") or {})
    extra["link"] = link
    ticks = [log.extra["tick"] for log in logs if "tick" in log.extra]
    if ticks:
        extra["tick"] = max(ticks, key=lambda t: float(t.get("late_pct") or 0.0))
    for key in ("mode", "estimates"):
        if key in lead.extra:
            extra[key] = lead.extra[key]
    extra["vehicle_kinds"] = [k for log in logs for k in log.extra.get("vehicle_kinds", [])]
    # per edge ("i<-j", "i+k<-j" for an agent of several vehicles: what that agent measured
    # of neighbour j's samples): ages at use, loss, clock offset
    edges: dict[str, Any] = {}
    for log in logs:
        agent = log.extra.get("agent") or {}
        own = "+".join(str(v) for v in agent.get("vehicles", []))
        for nb, fig in (agent.get("edges") or {}).items():
            edges[f"{own}<-{nb}"] = fig
    if edges:
        extra["edges"] = edges
    return FlightLog(
        t_s=grid,
        reference_velocity_enu_mps=_at(lead.t_s, lead.reference_velocity_enu_mps, grid),
        vehicle_ids=np.array(order),
        sysids=np.array([logs[where[v][0]].sysids[where[v][1]] for v in order]),
        offsets_enu_m=np.array([logs[where[v][0]].offsets_enu_m[where[v][1]] for v in order]),
        source=lead.source, controller=lead.controller, team=lead.team, name=name,
        extra=extra, **series)


def merge_records(agent_dirs: Sequence[Path], order: Sequence[int], out: Path, name: str,
                  agents: dict[str, Any], figures: bool,
                  pairs: Sequence[tuple[int, int]]) -> tuple[FlightLog, dict[str, Any]]:
    """Read each agent's timeseries.csv, write the team's report.json, timeseries.csv and
    (figures) its figures to `out`; returns the merged log and report."""
    logs = []
    for d in agent_dirs:
        path = d / TIMESERIES_NAME
        if not path.is_file():
            raise MergeError(f"{path}: missing (the agent wrote no formation log)")
        try:
            logs.append(load_timeseries(path))
        except (OSError, ValueError) as exc:
            raise MergeError(f"{path}: {exc}") from exc
    log = merge_logs(logs, order, name, agents)
    report = build_report(log)
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / REPORT_NAME, report)
    save_timeseries(log, out / TIMESERIES_NAME)
    if figures:
        from gcs.plots import write_figures

        write_figures(log, out, pairs=list(pairs))
    return log, report
