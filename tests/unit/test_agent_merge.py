"""The supervisor's merge of its agents' records into the team's."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gcs.agent.merge import MergeError, merge_records
from gcs.flightlog import FlightLog
from gcs.flightlog_csv import save_timeseries
from gcs.metrics import formation_error
from gcs.report import LINK_FIELDS, TICK_FIELDS

PERIOD = 0.02


def agent_log(ids, t0_k: int, k: int, rng, offsets) -> FlightLog:
    n = len(ids)
    t = (t0_k + np.arange(k)) * PERIOD + rng.uniform(0, 0.4 * PERIOD)
    tick = {f: 1.0 for f in TICK_FIELDS} | {"late_pct": float(rng.uniform(0, 2))}
    link = {str(v): {f: 1 for f in LINK_FIELDS} for v in ids}
    return FlightLog.from_arrays(
        t_s=t, position_enu_m=rng.normal(size=(k, n, 3)), velocity_enu_mps=rng.normal(size=(k, n, 3)),
        reference_velocity_enu_mps=np.tile(np.array([0.1, 0.2, 0.3]), (k, 1)),
        attitude_error=np.zeros((k, n)), omega_error_radps=np.zeros((k, n)),
        mass_estimate_kg=rng.uniform(1, 2, (k, n)), inertia_estimate_kgm2=np.ones((k, n, 3)),
        thrust_n=np.ones((k, n)), force_enu_n=np.ones((k, n, 3)), vehicle_ids=np.array(ids),
        offsets_enu_m=offsets, source="sim", controller="adaptive", team="t.yaml", name="t",
        extra={"tick": tick, "link": link, "vehicle_kinds": [f"PX4 {v}" for v in ids],
               "agent": {"vehicles": list(ids),
                         "edges": {str(ids[0] % 4 + 1): {"age_p50_ms": 12.0, "lost": 3}}}})


def test_the_team_log_has_every_vehicle_at_the_instants_all_agents_logged(tmp_path):
    rng = np.random.default_rng(0)
    offsets = {1: [0, 0, 0], 2: [1, 0, 0], 3: [0, 1, 0], 4: [1, 1, 0]}
    # GIVEN three agents (vehicles 3; 1 and 4; 2) whose logs start and end a little apart,
    # their ticks out of phase
    parts = [((3,), 0, 100), ((1, 4), 2, 100), ((2,), 1, 97)]
    dirs, logs = [], []
    for ids, k0, k in parts:
        log = agent_log(ids, k0, k, rng, np.array([offsets[v] for v in ids], dtype=float))
        d = tmp_path / f"agent-{ids[0]}"
        d.mkdir()
        save_timeseries(log, d / "timeseries.csv")
        dirs.append(d)
        logs.append(log)
    out = tmp_path / "team"
    merged, report = merge_records(dirs, (1, 2, 3, 4), out, "t", {"a": {}}, figures=False,
                                   pairs=[(1, 2)])
    # THEN the grid covers the span all logged, vehicles in team order
    assert merged.vehicle_ids.tolist() == [1, 2, 3, 4]
    lo = max(log.t_s[0] for log in logs)
    hi = min(log.t_s[-1] for log in logs)
    assert merged.t_s[0] >= lo and merged.t_s[-1] <= hi and merged.t_s[0] - lo < PERIOD
    np.testing.assert_allclose(np.diff(merged.t_s), PERIOD)
    # each vehicle's series is its agent's, interpolated to the grid's instants
    for col, (a, j) in ((0, (1, 0)), (2, (0, 0)), (3, (1, 1))):
        expect = np.interp(merged.t_s, logs[a].t_s, logs[a].position_enu_m[:, j, 1])
        np.testing.assert_allclose(merged.position_enu_m[:, col, 1], expect)
    # the team's formation error is over all four vehicles
    err = formation_error(merged.position_enu_m, merged.offsets_enu_m)
    assert err.shape == merged.t_s.shape and np.all(err > 0)
    written = json.loads((out / "report.json").read_text())
    assert [v["id"] for v in written["vehicles"]] == [1, 2, 3, 4]
    assert set(written["link"]) == {"1", "2", "3", "4"}
    assert written["tick"]["late_pct"] == max(log.extra["tick"]["late_pct"] for log in logs)
    assert (out / "timeseries.csv").is_file()
    # AND each agent's per-edge neighbour figures, named receiver <- neighbour
    edges = written["extra"]["edges"]
    assert edges["3<-4"] == {"age_p50_ms": 12.0, "lost": 3} and "2<-3" in edges
    assert "1+4<-2" in edges  # the agent of vehicles 1 and 4


def test_a_missing_vehicle_or_a_missing_log_is_a_clear_error(tmp_path):
    rng = np.random.default_rng(1)
    d = tmp_path / "a"
    d.mkdir()
    save_timeseries(agent_log((1,), 0, 10, rng, np.zeros((1, 3))), d / "timeseries.csv")
    with pytest.raises(MergeError, match=r"no agent's log has vehicles \[2\]"):
        merge_records([d], (1, 2), tmp_path / "o", "t", {}, figures=False, pairs=[])
    with pytest.raises(MergeError, match="missing"):
        merge_records([d, tmp_path / "none"], (1,), tmp_path / "o", "t", {}, figures=False,
                      pairs=[])
