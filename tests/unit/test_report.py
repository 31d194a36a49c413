"""Metrics against hand-computed values, and report.json against its schema (docs/report.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gcs import metrics
from gcs.flightlog import FlightLog
from gcs.frames import ned_from_enu
from gcs.report import (
    LINK_FIELDS,
    build_report,
    run_summary,
    summary_table,
    write_report,
)

OFFSETS = np.array([[2.0, 2.0, 0.0], [2.0, -2.0, 0.0], [-2.0, -2.0, 0.0], [-2.0, 2.0, 0.0]])
MASSES = np.array([0.85, 1.2, 0.35, 3.4])


def converging_log(
    dt: float = 0.01, t_end: float = 60.0, source: str = "sim", **overrides: object
) -> FlightLog:
    """A team of 4 converging exponentially (time constant 1.5 s) onto the square while
    tracking the paper's v_r; mass estimates converge at 1.5 /s."""
    k = int(round(t_end / dt)) + 1
    t = np.arange(k) / round(1 / dt)
    w = 2 * np.pi / 23
    vr = np.stack([0.3 * np.cos(w * t), 0.3 * np.cos(2 * w * t), np.full(k, 0.2)], axis=-1)
    centre = np.stack(
        [0.3 / w * np.sin(w * t), 0.3 / (2 * w) * np.sin(2 * w * t), 10 + 0.2 * t], axis=-1
    )
    d0 = np.array([[4, 4, 9], [3, -4, 11], [-5, -4, 12], [-1, 3, 8]], float) - OFFSETS
    d0 -= d0.mean(axis=0)
    decay = np.exp(-t / 1.5)[:, None, None]
    mass_est = MASSES + (np.array([0.5, 2, 0.5, 2]) - MASSES) * np.exp(-1.5 * t)[:, None]
    force = mass_est[..., None] * np.array([0.1, -0.1, 9.81])
    kwargs: dict[str, object] = {
        "t_s": t,
        "position_enu_m": centre[:, None, :] + OFFSETS + decay * d0,
        "velocity_enu_mps": vr[:, None, :] - decay * d0 / 1.5,
        "reference_velocity_enu_mps": vr,
        "attitude_error": np.array([0.026, 0.118, 0.173, 0.026]) * np.exp(-3 * t)[:, None],
        "omega_error_radps": np.array([0.3, 0.6, 0.8, 0.3]) * np.exp(-3 * t)[:, None],
        "mass_estimate_kg": mass_est,
        "mass_true_kg": MASSES,
        "inertia_estimate_kgm2": np.full((k, 4, 3), 0.08),
        "thrust_n": np.linalg.norm(force, axis=-1),
        "force_enu_n": force,
        "vehicle_ids": [1, 2, 3, 4],
        "sysids": [11, 12, 13, 14],
        "offsets_enu_m": OFFSETS,
        "source": source,
        "controller": "adaptive",
        "team": "configs/square4.yaml",
        "name": "square4",
    }
    kwargs.update(overrides)
    return FlightLog.from_arrays(**kwargs)  # type: ignore[arg-type]


LINK = {
    v: {
        "setpoints_sent": 6000,
        "telemetry_received": 5990,
        "telemetry_lost_pct": 0.17,
        "telemetry_age_p50_ms": 3.1,
        "telemetry_age_p99_ms": 9.4,
    }
    for v in (1, 2, 3, 4)
}
TICK = {"rate_hz": 100, "late_pct": 0.2, "lateness_p99_ms": 1.3}


# --------------------------------------------------------------------------------------------------
# Metrics


def test_perfect_formation_has_zero_error() -> None:
    # GIVEN every vehicle exactly at centre + theta_i
    p = np.array([5.0, -3.0, 12.0]) + OFFSETS
    assert metrics.formation_error(p, OFFSETS) == 0.0
    assert metrics.formation_error(p[None].repeat(3, axis=0), OFFSETS).tolist() == [0.0] * 3


def test_displaced_vehicle_gives_its_displacement() -> None:
    # GIVEN a perfect square WHEN vehicle 3 is displaced by (3, 4, 0) THEN every pair with it is
    # off by exactly 5 m and the others by 0, so the max over pairs is 5
    p = OFFSETS.copy()
    p[2] += [3.0, 4.0, 0.0]
    assert metrics.formation_error(p, OFFSETS) == pytest.approx(5.0, abs=1e-15)
    rel = metrics.relative_offsets(p, OFFSETS)  # pairs (0,1) (0,2) (0,3) (1,2) (1,3) (2,3)
    assert np.allclose(np.linalg.norm(rel, axis=-1), [0, 5, 0, 5, 0, 5])
    assert np.allclose(rel[1], [-3.0, -4.0, 0.0])  # p_1 - p_3 - theta_13


def test_formation_error_is_the_max_over_all_pairs_not_only_neighbours() -> None:
    # GIVEN vehicles 1 and 3 displaced in opposite directions (not ring neighbours)
    p = OFFSETS.copy()
    p[0] += [1.0, 0.0, 0.0]
    p[2] -= [1.0, 0.0, 0.0]
    assert metrics.formation_error(p, OFFSETS) == pytest.approx(2.0)
    assert metrics.formation_error(p[:1], OFFSETS[:1]) == 0.0  # one vehicle: no pair


def test_formation_error_of_a_series_is_each_sample_s_dense_pair_maximum() -> None:
    # GIVEN a (2, 3, n, 3) batch of samples of 7 vehicles, one sample with an unknown position
    rng = np.random.default_rng(3)
    p = rng.normal(0.0, 2.0, (2, 3, 7, 3))
    theta = rng.normal(0.0, 2.0, (7, 3))
    p[1, 2, 4, 0] = np.nan
    # WHEN the series' error is taken
    got = metrics.formation_error(p, theta)
    # THEN it has the batch's shape and is, per sample, the largest |p_i - p_j - theta_ij|
    q = p - theta
    dense = np.linalg.norm(q[..., :, None, :] - q[..., None, :, :], axis=-1).max(axis=(-2, -1))
    assert got.shape == (2, 3)
    np.testing.assert_allclose(got[~np.isnan(dense)], dense[~np.isnan(dense)], rtol=1e-14)
    assert np.isnan(got[1, 2]) and np.isnan(got).sum() == 1
    with pytest.raises(ValueError, match="offsets"):
        metrics.formation_error(p, theta[:6])


coords = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    p=hnp.arrays(np.float64, (5, 4, 3), elements=coords),
    shift=hnp.arrays(np.float64, (3,), elements=coords),
)
def test_formation_error_is_translation_invariant(p: np.ndarray, shift: np.ndarray) -> None:
    # GIVEN any positions WHEN the whole team is translated THEN the error is unchanged
    before = metrics.formation_error(p, OFFSETS)
    after = metrics.formation_error(p + shift, OFFSETS)
    assert np.allclose(before, after, rtol=0, atol=1e-9)
    # and translating the offsets does not matter either (theta is defined up to a common shift)
    assert np.allclose(before, metrics.formation_error(p, OFFSETS + shift), rtol=0, atol=1e-9)
    assert np.all(before >= 0)


def test_velocity_error_is_the_worst_vehicle() -> None:
    # GIVEN at sample 0 vehicle 2 off v_r by (0, 3, 4); at sample 1 both exactly on v_r
    v = np.array([[[1.0, 0.0, 0.0], [1.0, 3.0, 4.0]], [[0.0, 0.0, 0.2], [0.0, 0.0, 0.2]]])
    vr = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.2]])
    assert metrics.velocity_error(v, vr).tolist() == [5.0, 0.0]
    with pytest.raises(ValueError, match="expected velocity"):
        metrics.velocity_error(v, vr[0])


def test_time_series_helpers() -> None:
    t = np.arange(11) / 10  # 0.0 .. 1.0
    x = np.array([5, 4, 3, 0.5, 2, 0.5, 0.4, 0.3, 0.2, 0.1, 0.05])
    assert metrics.value_at(t, x, 0.3) == 0.5
    assert metrics.value_at(t, x, 0.34) == 0.5 and metrics.value_at(t, x, 0.36) == 2.0
    with pytest.raises(ValueError, match="outside the log"):
        metrics.value_at(t, x, 1.2)
    assert metrics.max_over_window(t, x) == 5.0
    assert metrics.max_over_window(t, x, 0.35, 1.0) == 2.0
    assert metrics.min_over_window(t, x, 0.0, 0.5) == 0.5
    with pytest.raises(ValueError, match="no sample in the window"):
        metrics.max_over_window(t, x, 2.0, 3.0)
    # settling: below 1 from t = 0.5 on (the dip at 0.3 does not count)
    assert metrics.convergence_time(t, x, 1.0) == 0.5
    assert metrics.convergence_time(t, x, 10.0) == 0.0
    assert metrics.convergence_time(t, x, 0.01) is None
    y = x.copy()
    y[-1] = np.nan
    assert metrics.convergence_time(t, y, 1.0) is None  # unknown at the end: not converged
    assert metrics.max_over_window(t, y) == 5.0  # NaN samples are ignored by max
    per_vehicle = np.stack([x, 2 * x], axis=1)
    assert metrics.max_over_window(t, per_vehicle).tolist() == [5.0, 10.0]


def test_grid_indices_picks_multiples_and_marks_gaps() -> None:
    # GIVEN a 1 kHz log from t = -0.25 s to 0.5 s with the samples of [0.19, 0.21] missing
    t = np.arange(-250, 501) / 1000
    t = t[(t < 0.19) | (t > 0.21)]
    grid, idx = metrics.grid_indices(t, 0.1)
    assert grid.tolist() == [-0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5]  # exact decimals
    assert [t[i] for i in idx if i >= 0] == [-0.2, -0.1, 0.0, 0.1, 0.3, 0.4, 0.5]
    assert idx[4] == -1  # 0.2 falls in the gap
    # a log coarser than the grid: grid times without a sample within 0.05 s are gaps
    grid, idx = metrics.grid_indices(np.array([0.0, 0.3, 0.6]), 0.1)
    assert grid.tolist() == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    assert idx.tolist() == [0, -1, -1, 1, -1, -1, 2]
    # jittered fly timestamps (100 Hz +- 3 ms) still map onto the nearest tick
    t = np.arange(0, 101) / 100 + np.random.default_rng(1).uniform(-0.003, 0.003, 101)
    t[0], t[-1] = 0.002, 0.998  # the first and last tick a little off the grid
    grid, idx = metrics.grid_indices(np.sort(t), 0.1)
    assert grid[0] == 0.0 and grid[-1] == 1.0
    assert np.all(idx >= 0) and np.all(np.abs(np.sort(t)[idx] - grid) <= 0.003)


# --------------------------------------------------------------------------------------------------
# Report


def test_report_has_every_mandatory_field_with_the_right_shape_and_type() -> None:
    # GIVEN a 60 s sim log at 100 Hz WHEN the report is built
    log = converging_log()
    r = build_report(log)
    k, n = 601, 4
    assert r["schema"] == "formation-flight-report/1"
    assert (r["source"], r["controller"], r["team"]) == ("sim", "adaptive", "configs/square4.yaml")
    assert r["vehicles"] == [
        {
            "id": i + 1,
            "sysid": 11 + i,
            "mass_true_kg": MASSES[i],
            "offset_ned_m": ned_from_enu(OFFSETS[i]).tolist(),
        }
        for i in range(n)
    ]
    assert all(type(v["id"]) is int and type(v["sysid"]) is int for v in r["vehicles"])
    for name in ("t_s", "formation_error_m", "velocity_error_mps", "attitude_error"):
        assert len(r[name]) == k and all(type(x) is float for x in r[name]), name
    for name in ("mass_estimate_kg", "mass_true_kg", "thrust_n"):
        assert np.shape(r[name]) == (k, n) and type(r[name][0][0]) is float, name
    for name in ("position_ned_m", "velocity_ned_mps"):
        assert np.shape(r[name]) == (k, n, 3) and type(r[name][0][0][0]) is float, name
    assert "link" not in r and "tick" not in r  # sim: left out
    # THEN the values are the log's at the picked samples
    assert r["formation_error_m"][0] == pytest.approx(
        metrics.formation_error(log.position_enu_m[0], OFFSETS)
    )
    assert r["attitude_error"][0] == pytest.approx(0.173)
    assert r["mass_estimate_kg"][100] == log.mass_estimate_kg[1000].tolist()  # t = 10 s
    assert r["thrust_n"][-1] == log.thrust_n[-1].tolist()


def test_report_samples_every_tenth_of_a_second() -> None:
    # GIVEN a 1 kHz log from t = 0 to 3 s
    r = build_report(converging_log(dt=0.001, t_end=3.0))
    t = np.array(r["t_s"])
    assert r["t_s"][:4] == [0.0, 0.1, 0.2, 0.3] and r["t_s"][-1] == 3.0
    assert np.allclose(np.diff(t), 0.1, rtol=0, atol=1e-12)
    assert r["log_period_s"] == pytest.approx(0.001)


def test_report_positions_and_velocities_are_local_ned() -> None:
    # GIVEN vehicle 1 at ENU (1, 2, 3) m (east 1, north 2, up 3) climbing at 0.5 m/s
    log = converging_log(t_end=1.0)
    p = np.array(log.position_enu_m)
    v = np.array(log.velocity_enu_mps)
    p[:, 0] = [1.0, 2.0, 3.0]
    v[:, 0] = [0.1, -0.2, 0.5]
    r = build_report(converging_log(t_end=1.0, position_enu_m=p, velocity_enu_mps=v))
    # THEN NED is (north, east, down) = (2, 1, -3): "up" is negative d
    assert r["position_ned_m"][3][0] == [2.0, 1.0, -3.0]
    assert r["velocity_ned_mps"][3][0] == [-0.2, 0.1, -0.5]
    assert r["vehicles"][1]["offset_ned_m"] == [-2.0, 2.0, 0.0]  # ENU (2, -2, 0): 2 m south


def test_unknown_values_are_null_and_the_json_has_no_nan_tokens(tmp_path: Path) -> None:
    # GIVEN real vehicles (true mass unknown) and one lost telemetry sample of vehicle 2
    log = converging_log(t_end=2.0, source="fly", mass_true_kg=None)
    p = np.array(log.position_enu_m)
    p[50, 1] = np.nan  # t = 0.5 s
    log = converging_log(t_end=2.0, source="fly", mass_true_kg=None, position_enu_m=p)
    r = build_report(log, link=LINK, tick=TICK)
    assert r["vehicles"][0]["mass_true_kg"] is None
    assert r["mass_true_kg"][0] == [None] * 4
    assert r["position_ned_m"][5][1] == [None, None, None]
    assert r["formation_error_m"][5] is None  # the max over pairs is unknown
    assert r["formation_error_m"][4] is not None
    # WHEN written THEN strict JSON: no NaN / Infinity tokens, and null where unknown
    path = write_report(tmp_path / "report.json", {**r, "bad": [math.nan, math.inf, -math.inf]})
    text = path.read_text()
    for token in ("NaN", "Infinity"):
        assert token not in text
    back = json.loads(text, parse_constant=lambda c: pytest.fail(f"token {c}"))
    assert back["bad"] == [None, None, None]
    assert back["mass_true_kg"][0] == [None] * 4
    assert back["t_s"] == r["t_s"]


def test_link_and_tick_appear_for_fly_and_are_checked() -> None:
    log = converging_log(t_end=1.0, source="fly")
    r = build_report(log, link=LINK, tick=TICK)
    assert sorted(r["link"]) == ["1", "2", "3", "4"]
    assert set(r["link"]["1"]) == set(LINK_FIELDS)
    assert r["tick"] == TICK
    # from the log's extra when not passed
    r2 = build_report(converging_log(t_end=1.0, source="fly", extra={"link": LINK, "tick": TICK}))
    assert r2["link"] == r["link"] and r2["tick"] == TICK and "extra" not in r2
    with pytest.raises(ValueError, match="link and tick statistics are mandatory"):
        build_report(log)
    with pytest.raises(ValueError, match=r"no statistics for vehicles \[4\]"):
        build_report(log, link={k: v for k, v in LINK.items() if k != 4}, tick=TICK)
    with pytest.raises(ValueError, match=r"link\['2'\]: missing fields \['telemetry_age_p99_ms'\]"):
        bad = {**LINK, 2: {k: v for k, v in LINK[2].items() if k != "telemetry_age_p99_ms"}}
        build_report(log, link=bad, tick=TICK)
    with pytest.raises(ValueError, match=r"tick: missing fields \['late_pct'\]"):
        build_report(log, link=LINK, tick={"rate_hz": 100, "lateness_p99_ms": 1.0})


def test_report_round_trips_through_json(tmp_path: Path) -> None:
    r = build_report(converging_log(t_end=5.0, extra={"mass_drop_t_s": 40.0}))
    assert r["extra"] == {"mass_drop_t_s": 40.0}
    back = json.loads(write_report(tmp_path / "r.json", r).read_text())
    assert back == r


def test_summary_figures_and_table() -> None:
    # GIVEN the converging log (formation error decays like exp(-t/1.5))
    log = converging_log(t_end=30.0)
    s = run_summary(log)
    assert list(s["formation_error_m_at"]) == ["5", "10", "20", "30"]  # 60 s is not in the run
    e0 = metrics.formation_error(log.position_enu_m[0], OFFSETS)
    assert s["formation_error_m_at"]["10"] == pytest.approx(e0 * math.exp(-10 / 1.5), rel=1e-9)
    assert s["vehicles"]["mass_estimate_kg_at_10s"] == pytest.approx(MASSES, abs=1e-5)
    assert s["vehicles"]["peak_thrust_n"] == pytest.approx(log.thrust_n.max(axis=0).tolist())
    assert s["vehicles"]["min_force_up_n"] == pytest.approx(log.force_enu_n[..., 2].min(axis=0))
    assert s["max_attitude_error"] == pytest.approx(0.173)
    assert 0 < s["formation_converged_t_s"] < 10
    text = summary_table(log)
    lines = text.splitlines()
    assert lines[0].startswith("run 'square4': sim, adaptive, team configs/square4.yaml")
    for label in (
        "formation error at t = 5 s",
        "formation error at t = 30 s",
        "velocity error at end",
        "max attitude error",
        "m_est@10s",
        "peak T[N]",
        "min u_z[N]",
    ):
        assert label in text, label
    assert "t = 60 s" not in text
    assert len(lines) < 25 and all(len(line) < 100 for line in lines)
    assert "\x1b" not in text  # plain text, no terminal escapes
    # a short run without the 10 s checkpoint and with unknown true masses still renders
    short = summary_table(converging_log(t_end=2.0, mass_true_kg=None))
    assert "m_est@10s" not in short and " - " in short


def flown_log(hold_m: float, t_end: float = 40.0) -> FlightLog:
    """The converging log as flown: UAV 1 keeps a `hold_m` wander along x (1 Hz) once the
    formation has converged, and one tick at 20 s is unknown (NaN, a skipped tick)."""
    log = converging_log(t_end=t_end, source="fly")
    position = log.position_enu_m.copy()
    position[:, 0, 0] += hold_m * np.sin(2 * np.pi * log.t_s)
    position[2000] = np.nan
    return converging_log(t_end=t_end, source="fly", position_enu_m=position)


@pytest.mark.parametrize(("hold_m", "below_m"), [(0.04, 0.05), (0.3, 0.5), (0.8, 1.0)])
def test_a_flight_s_summary_states_a_threshold_its_formation_error_meets(hold_m, below_m):
    # GIVEN a flight that holds its formation to hold_m (decimetres, as flown vehicles do), with
    # one unknown sample
    log = flown_log(hold_m)
    # WHEN summarised
    s = run_summary(log)
    text = summary_table(log)
    # THEN the convergence row names the smallest of 0.01 / 0.02 / 0.05 ... 1 m the flight stays
    # below,
    # and a time (not the constant "-" of the simulation's 0.01 m)
    assert s["formation_converged_below_m"] == below_m
    assert 0 < s["formation_converged_t_s"] < 10
    row = next(line for line in text.splitlines() if "stays <" in line)
    assert row.split()[:6] == ["formation", "error", "stays", "<", f"{below_m:g}", "m"]
    assert row.split()[-1] == f"{s['formation_converged_t_s']:.2f}"


def test_a_simulation_s_summary_keeps_the_0_01_m_threshold():
    # GIVEN a simulated run whose formation error decays to micrometres, as gcs sim's do
    log = converging_log(t_end=40.0)
    # WHEN summarised THEN it is judged against 0.01 m, as before
    s = run_summary(log)
    assert s["formation_converged_below_m"] == 0.01
    assert s["formation_converged_t_s"] == metrics.convergence_time(
        log.t_s, metrics.formation_error(log.position_enu_m, OFFSETS), 0.01)
    row = next(line for line in summary_table(log).splitlines() if "stays <" in line)
    assert row.split()[4:6] == ["0.01", "m"] and row.split()[-1] != "-"
