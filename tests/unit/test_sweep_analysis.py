"""The sweep analysis on synthetic results tables whose answers are known by construction."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pytest
from scipy import stats

from gcs.sweep import analysis
from gcs.sweep.analysis import AnalysisMeta, write_analysis
from gcs.sweep.plots import axis_label, unit

MASS = "param.vehicles.2.plant.mass_kg"
DELAY = "param.link.delay_s"
MODE = "param.controller.mode"
TEMPLATE = "gcs sim --study study.yaml --run {run} --out runs/replay-{run}"


def results(params: dict[str, list | np.ndarray], **columns: list | np.ndarray) -> pa.Table:
    """A results table of the fixed schema: the given parameter and metric columns, every other
    metric a plausible default (status ok, converged, errors 0.01 m, conditions held)."""
    n = len(next(iter(params.values()))) if params else len(next(iter(columns.values())))
    floats = {"converge_time_s": 10.0, "final_error_m": 0.001, "max_error_m": 0.01,
              "mean_error_m": 0.005, "mass_error_pct": 1.0, "saturation_share": 0.1,
              "min_distance_m": 2.0, "min_force_up_n": 5.0}
    data: dict[str, pa.Array] = {"run": pa.array(np.arange(n), pa.int64()),
                                 "seed": pa.array(np.arange(n) + 1000, pa.int64())}
    data |= {name: pa.array(values) for name, values in params.items()}
    data["status"] = pa.array(["ok"] * n, pa.string())
    for name in analysis.BOOL_METRICS:
        data[name] = pa.array([True] * n, pa.bool_())
    for name, value in floats.items():
        data[name] = pa.array(np.full(n, value), pa.float64())
    data["message"] = pa.array([""] * n, pa.string())
    for name, values in columns.items():
        data[name] = pa.array(values, type=data[name].type)
    return pa.table(data)


def meta(**changes) -> AnalysisMeta:
    fields = {"study_name": "synthetic", "study_file": "study.yaml", "runs_planned": 100,
              "replay_template": TEMPLATE, "window_start_s": 30.0, "converged_below_m": 0.01}
    return AnalysisMeta(**(fields | changes))


def strict_json(text: str):
    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")
    return json.loads(text, parse_constant=refuse)


# --- statistics ----------------------------------------------------------------------------


@pytest.mark.parametrize(("k", "n"), [(0, 1), (1, 1), (0, 10), (10, 10), (3, 7), (50, 100),
                                      (999, 1000), (1, 3000)])
def test_wilson_interval_matches_scipy(k, n):
    # GIVEN k successes of n WHEN the interval is computed THEN it is scipy's Wilson interval
    expected = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    low, high = analysis.wilson_interval(k, n)
    assert low == pytest.approx(expected.low, abs=1e-12)
    assert high == pytest.approx(expected.high, abs=1e-12)


def test_wilson_interval_of_no_runs_is_unknown():
    assert all(math.isnan(v) for v in analysis.wilson_interval(0, 0))


def test_float_stats_exclude_and_count_nan_and_match_scipy_t_interval():
    # GIVEN five values and two NaN
    values = np.array([1.0, np.nan, 2.0, 4.0, np.nan, 8.0, 5.0])
    finite = np.array([1.0, 2.0, 4.0, 8.0, 5.0])
    s = analysis.float_stats(values)
    # THEN the NaN are counted, not used, and the mean's interval is Student's t
    assert (s.n, s.nan) == (5, 2)
    assert (s.mean, s.median, s.min, s.max) == (4.0, 4.0, 1.0, 8.0)
    low, high = stats.t.interval(0.95, 4, loc=4.0, scale=stats.sem(finite))
    assert (s.mean_low, s.mean_high) == (pytest.approx(low), pytest.approx(high))
    # p5 / p95 by linear interpolation over the sorted values 1 2 4 5 8 (positions 0.2 and 3.8)
    assert (s.p5, s.p95) == (pytest.approx(1.2), pytest.approx(7.4))


def test_float_stats_of_nothing_and_of_one_value():
    empty = analysis.float_stats(np.array([np.nan, np.nan]))
    assert (empty.n, empty.nan) == (0, 2) and math.isnan(empty.mean)
    one = analysis.float_stats(np.array([3.0]))
    assert (one.n, one.mean, one.median) == (1, 3.0, 3.0)
    assert math.isnan(one.mean_low) and math.isnan(one.mean_high)


def test_rates_count_the_runs_that_ran_and_a_divergence_fails():
    # GIVEN 4 ok (3 converged), 2 diverged and 1 error; one ok run's conditions_held is null
    status = ["ok", "ok", "ok", "ok", "diverged", "diverged", "error"]
    converged = [True, True, True, False, False, False, False]
    held = [True, None, False, True, False, False, False]
    table = results({MASS: np.linspace(0.5, 1.5, 7)}, status=status, converged=converged,
                    conditions_held=held)
    summary = analysis.summarize(table, runs_planned=10)
    # THEN success is 3 of the 6 that ran; conditions_held 1 of the 5 known, 1 null
    assert summary.status_counts == {"ok": 4, "diverged": 2, "error": 1}
    assert (summary.success.k, summary.success.n) == (3, 6)
    held_rate = summary.rates["conditions_held"]
    assert (held_rate.k, held_rate.n, held_rate.missing) == (2, 5, 1)


# --- bins ----------------------------------------------------------------------------------


def shuffled_masses(seed: int = 7) -> np.ndarray:
    """0.50, 0.51, ..., 1.49 kg in random order: deciles hold exactly ten values each."""
    return np.random.default_rng(seed).permutation(0.5 + 0.01 * np.arange(100))


@pytest.mark.parametrize(("threshold", "expected"), [
    (1.0, [1, 1, 1, 1, 1, 0, 0, 0, 0, 0]),
    (0.95, [1, 1, 1, 1, 0.5, 0, 0, 0, 0, 0]),
    (0.555, [0.6, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
])
def test_quantile_bins_step_where_success_steps(threshold, expected):
    # GIVEN 100 runs, mass 0.50..1.49 kg, success iff mass < threshold
    mass = shuffled_masses()
    table = results({MASS: mass}, converged=mass < threshold)
    bins = analysis.bin_parameter(table, MASS)
    rate = analysis.binned_rate(bins, analysis.successes(table), analysis.ran(table))
    # THEN ten quantile bins of ten runs, with the hand-counted rates
    assert bins.quantiles and list(rate.n) == [10] * 10
    assert rate.rate == pytest.approx(expected)
    for b in range(10):
        assert bins.lows[b] == pytest.approx(0.5 + 0.1 * b, abs=0.01)


def test_each_run_lies_in_its_bins_range_ties_at_an_edge_included():
    # GIVEN 150 runs, a third of them at exactly 1.0 (a quantile edge)
    mass = np.concatenate([np.full(50, 1.0), np.linspace(0.5, 0.99, 50),
                           np.linspace(1.01, 2.0, 50)])
    bins = analysis.bin_parameter(results({MASS: mass}), MASS)
    # THEN run r lies in [low, high) of its bin (the last bin closed)
    low, high = bins.lows[bins.index], bins.highs[bins.index]
    last = bins.index == len(bins.labels) - 1
    assert bins.quantiles and np.all(low <= mass)
    assert np.all((mass < high) | (last & (mass == high)))
    assert np.sum(bins.lows == 1.0) == 1


def test_few_runs_get_fewer_quantile_bins_and_nan_values_no_bin():
    # GIVEN 35 distinct masses and 3 NaN
    mass = np.concatenate([np.linspace(0.5, 1.5, 35), [np.nan] * 3])
    table = results({MASS: mass})
    bins = analysis.bin_parameter(table, MASS)
    # THEN 3 bins (about ten runs each) hold the 35; the NaN are in none
    assert len(bins.labels) == 3
    assert np.sum(bins.index >= 0) == 35 and list(bins.index[-3:]) == [-1, -1, -1]


def test_a_parameter_with_few_values_gets_a_bin_per_value():
    # GIVEN delays 0, 0.1, 0.2 s; success fails at 0.2 s in all, at 0.1 s in one of three
    delay = [0.0, 0.1, 0.2, 0.0, 0.1, 0.2, 0.1, 0.0]
    converged = [True, True, False, True, False, False, True, True]
    table = results({DELAY: delay}, converged=converged)
    rate = analysis.binned_rate(analysis.bin_parameter(table, DELAY),
                                analysis.successes(table), analysis.ran(table))
    assert not rate.bins.quantiles
    assert list(rate.bins.lows) == [0.0, 0.1, 0.2]
    assert list(rate.k) == [3, 2, 0] and list(rate.n) == [3, 3, 2]


def test_string_parameter_bins_per_value_and_errors_are_not_counted():
    mode = ["rates", "attitude", "rates", "attitude", "rates", None]
    status = ["ok", "ok", "diverged", "ok", "error", "ok"]
    converged = [True, False, False, True, False, True]
    table = results({MODE: mode}, status=status, converged=converged)
    rate = analysis.binned_rate(analysis.bin_parameter(table, MODE),
                                analysis.successes(table), analysis.ran(table))
    # THEN attitude 1 of 2, rates 1 of 2 (the error run and the missing mode are in no bin)
    assert rate.bins.labels == ("attitude", "rates")
    assert list(rate.k) == [1, 1] and list(rate.n) == [2, 2]


def test_cells_count_success_and_median_error_by_hand():
    # GIVEN two delays x two modes; max errors chosen per cell
    delay = [0.0, 0.0, 0.0, 0.2, 0.2, 0.0, 0.2]
    mode = ["a", "a", "b", "a", "b", "b", "b"]
    converged = [True, False, True, False, False, True, True]
    max_error = [0.1, 0.3, 0.2, 5.0, np.nan, 0.4, 1.0]
    table = results({DELAY: delay, MODE: mode}, converged=converged, max_error_m=max_error)
    grid = analysis.cells(analysis.bin_parameter(table, DELAY),
                          analysis.bin_parameter(table, MODE), analysis.successes(table),
                          analysis.ran(table), analysis.floats(table, "max_error_m"))
    assert grid.n.tolist() == [[2, 2], [1, 2]]
    assert grid.k.tolist() == [[1, 2], [0, 1]]
    assert grid.median_max_error_m == pytest.approx(np.array([[0.2, 0.3], [5.0, 1.0]]))


def test_heatmap_pair_defaults_to_the_most_varied_parameters():
    n = 30
    table = results({MASS: np.linspace(0.5, 1.5, n), "param.k": np.tile([1.0, 2.0, 3.0], 10),
                     "param.c": np.full(n, 4.0), DELAY: np.tile([0.0, 0.1, 0.2, 0.3, 0.4], 6)})
    assert analysis.heatmap_pair(table, None) == (MASS, DELAY)
    assert analysis.heatmap_pair(results({"param.c": np.ones(n)}), None) is None
    with pytest.raises(ValueError, match="param.nope is not a parameter column"):
        analysis.heatmap_pair(table, (MASS, "param.nope"))


# --- worst runs and the report -------------------------------------------------------------


def ordering_table() -> pa.Table:
    status = ["ok", "ok", "diverged", "error", "ok", "ok", "diverged", "ok"]
    converged = [True, False, False, False, True, True, False, False]
    max_error = [0.1, 0.5, np.nan, np.nan, 0.9, 0.3, np.nan, 2.0]
    table = results({MASS: np.linspace(0.5, 1.2, 8)}, status=status, converged=converged,
                    max_error_m=max_error, message=["", "", "", "boom", "", "", "", ""])
    # run numbers differ from row indices: a resumed sweep's rows need not be in run order
    return table.set_column(0, "run", pa.array([7, 6, 5, 4, 3, 2, 1, 0], pa.int64()))


def test_worst_runs_list_failures_first_then_the_largest_error():
    # rows 2, 6 diverged (run 5, run 1: the lower run first), 3 error, 7 and 1 ok but not
    # converged (max error 2.0, then 0.5), then the converged by max error: 4, 5, 0
    table = ordering_table()
    assert analysis.worst_runs(table, 10) == [6, 2, 3, 7, 1, 4, 5, 0]
    assert analysis.worst_runs(table, 3) == [6, 2, 3]
    assert analysis.worst_runs(table, 0) == []


def test_report_names_the_worst_run_with_its_replay_command(tmp_path):
    table = ordering_table()
    write_analysis(table, meta(worst_count=4), tmp_path)
    report = (tmp_path / "report.md").read_text()
    # THEN the first listed run is run 1 (diverged), replayed by the template with its number
    first = report.index("### 1. run 1 (seed 1006): diverged")
    assert "gcs sim --study study.yaml --run 1 --out runs/replay-1" in report[first:]
    assert "Message: boom" in report
    assert "### 4. run 0" in report and "### 5." not in report
    assert "5 of 8 runs are not ok or did not converge" in report
    # the figures are linked
    assert "![heatmap](heatmap.png)" in report
    assert f"(success_vs_{MASS.removeprefix('param.')}.png)" in report


def test_summary_json_is_strict_and_its_intervals_are_scipy_wilson(tmp_path):
    # GIVEN 40 runs, success iff mass < 1 kg (13 of 40), the failed ones diverged
    mass = np.linspace(0.5, 1.5, 40)
    ok = mass < 1.0
    nan = np.where(ok, 0.01, np.nan)
    table = results({MASS: mass}, status=np.where(ok, "ok", "diverged"), converged=ok,
                    max_error_m=nan, converge_time_s=nan, final_error_m=nan)
    write_analysis(table, meta(runs_planned=50), tmp_path)
    record = strict_json((tmp_path / "summary.json").read_text())
    assert (record["runs_done"], record["runs_planned"]) == (40, 50)
    assert record["status"] == {"ok": 20, "diverged": 20, "error": 0}
    expected = stats.binomtest(20, 40).proportion_ci(confidence_level=0.95, method="wilson")
    assert record["success"]["ci95_wilson"] == pytest.approx([expected.low, expected.high])
    assert record["metrics"]["max_error_m"]["nan"] == 20


# --- edge cases ----------------------------------------------------------------------------


def edge_tables() -> dict[str, pa.Table]:
    n = 12
    rng = np.random.default_rng(3)
    nan = np.full(n, np.nan)
    return {
        "empty": results({MASS: np.array([]), MODE: pa.array([], pa.string())}, status=[]),
        "no parameters": results({}, status=["ok", "diverged"]),
        "all diverged": results({MASS: rng.uniform(0.5, 1.5, n), DELAY: rng.uniform(0, 0.2, n)},
                                status=["diverged"] * n, converged=[False] * n,
                                converge_time_s=nan, max_error_m=nan, mean_error_m=nan,
                                final_error_m=nan, mass_error_pct=nan),
        "single run": results({MASS: [0.9], DELAY: [0.1], MODE: ["rates"]}),
        "constant parameters": results({MASS: np.ones(n), MODE: ["rates"] * n}),
        "NaN parameters": results({MASS: nan, DELAY: rng.uniform(0, 0.2, n)},
                                  converged=[None] * n),
        "all errors": results({MASS: rng.uniform(0.5, 1.5, n)}, status=["error"] * n,
                              message=["failed"] * n),
    }


@pytest.mark.parametrize("name", list(edge_tables()))
def test_edge_tables_give_every_file_and_strict_json(tmp_path, name):
    table = edge_tables()[name]
    written = write_analysis(table, meta(), tmp_path / "out")
    names = [p.name for p in written]
    assert names[:2] == ["summary.json", "summary.md"] and names[-1] == "report.md"
    assert {"ecdf_converge_time.png", "heatmap.png"} <= set(names)
    params = analysis.param_columns(table)
    assert sum(n.startswith("success_vs_") for n in names) == len(params)
    assert all(p.stat().st_size > 0 for p in written)
    record = strict_json((tmp_path / "out" / "summary.json").read_text())
    assert record["runs_done"] == table.num_rows
    report = (tmp_path / "out" / "report.md").read_text()
    if table.num_rows == 0:
        assert "No runs in the table." in report
        assert record["success"]["rate"] is None


def test_a_table_without_a_schema_column_is_refused():
    table = results({MASS: [1.0]}).drop_columns(["max_error_m", "cond.prop1"])
    with pytest.raises(ValueError, match="missing columns cond.prop1, max_error_m"):
        write_analysis(table, meta(), "unused")


def test_meta_refuses_a_template_without_the_run():
    with pytest.raises(ValueError, match="replay_template: expected '\\{run\\}'"):
        meta(replay_template="gcs sim --study study.yaml")


def test_figures_of_parameters_no_longer_in_the_table_are_removed(tmp_path):
    write_analysis(results({MASS: [1.0, 2.0]}), meta(), tmp_path)
    write_analysis(results({DELAY: [0.1, 0.2]}), meta(), tmp_path)
    assert [p.name for p in tmp_path.glob("success_vs_*.png")] == ["success_vs_link.delay_s.png"]


@pytest.mark.parametrize(("path", "expected"), [
    ("vehicles.1.initial.position_enu_m.0", "m"), ("vehicles.2.plant.mass_kg", "kg"),
    ("vehicles.0.plant.inertia_kgm2.2", "kg m²"), ("link.delay_s", "s"),
    ("link.loss_pct", "%"), ("controller.mode", None),
])
def test_units_come_from_the_key_suffix(path, expected):
    assert unit(path) == expected


def test_axis_label_drops_the_prefix_and_adds_the_unit():
    assert axis_label(MASS) == "vehicles.2.plant.mass_kg [kg]"
    assert axis_label(MODE) == "controller.mode"
