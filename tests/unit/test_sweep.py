"""gcs sweep's core: study files, per-run draws, batched runs equal to single ones, measurement,
the result store's resume."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from gcs.config import ConfigError, load_team
from gcs.flightlog import FlightLog
from gcs.sim.runner import SimOptions, simulate, simulate_batch
from gcs.sweep.measure import METRICS, min_distance_m, run_row
from gcs.sweep.store import ResultStore, batches
from gcs.sweep.study import StudyMetrics, load_study
from gcs.sweep.work import fly_runs

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def write_study(tmp_path: Path, body: str, name: str = "study.yaml") -> Path:
    path = tmp_path / name
    head = f"name: t\nteam: {CONFIGS / 'square4.yaml'}\nruns: 8\nseed: 7\n"
    path.write_text(head + textwrap.dedent(body))
    return path


SMALL = """\
set:
  controller.mode: rates
  sim.controller_rate_hz: 100
  mission.duration_s: 4.0
parameters:
  - key: vehicles[*].plant.mass_kg
    scale: {uniform: [0.8, 1.0]}
  - key: vehicles[*].initial.position_enu_m
    add: {uniform: [-0.5, 0.5]}
    each: component
"""


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("parameters:\n  - key: vehicles[*].plant.mass\n    scale: {uniform: [0.5, 1.5]}\n",
         "parameters[0].key: the base team has no key 'vehicles[*].plant.mass'"),
        ("parameters:\n  - key: vehicles[*].plant.mass_kg\n    scale: {uniform: [1.5, 0.5]}\n",
         "parameters[0].scale.uniform: expected low < high, got [1.5, 0.5]"),
        ("parameters:\n  - key: controller.mode\n    scale: {uniform: [0.5, 1.5]}\n",
         "scale needs a number or a list of numbers at 'controller.mode'"),
        ("parameters:\n  - key: vehicles[9].plant.mass_kg\n    scale: {normal: [1, 0.1]}\n",
         "'vehicles[9].plant.mass_kg' names no vehicle of the base team"),
        ("parameters:\n  - key: vehicles[*].plant.mass_kg\n    scale: {choice: [1, 2]}\n",
         "choice draws whole values: use it with `value`"),
        ("parameters:\n  - key: vehicles[*].plant.mass_kg\n    scale: {normal: [1, 0]}\n",
         "the standard deviation must be > 0"),
        ("paramters: []\n", "unknown key; did you mean 'parameters'?"),
        ("set:\n  controller.gains.c_p: -1\nparameters:\n  - key: sim.plant_rate_hz\n"
         "    value: {choice: [1000]}\n",
         "the base team with these keys set is not a valid team"),
    ],
)
def test_a_bad_study_is_one_error_naming_its_key_and_line(tmp_path, body, message):
    # GIVEN a study with one mistake WHEN it is read THEN one ConfigError names it
    path = write_study(tmp_path, body)
    with pytest.raises(ConfigError) as err:
        load_study(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_a_run_draws_the_same_team_every_time_and_its_own_numbers(tmp_path):
    study = load_study(write_study(tmp_path, SMALL))
    # WHEN run 3 is drawn twice and run 4 once
    a, pa = study.draw(3)
    b, pb = study.draw(3)
    _, pc = study.draw(4)
    # THEN run 3 is the same both times and run 4 differs
    assert a == b and pa == pb
    assert pa != pc
    # AND every drawn mass is within its factor of the base's, recorded under its column
    base = load_team(CONFIGS / "square4.yaml")
    for v in base.vehicles:
        drawn = pa[f"param.vehicles.{v.id}.plant.mass_kg"]
        assert 0.8 * v.plant.mass_kg <= drawn <= v.plant.mass_kg
        for k in range(3):
            moved = pa[f"param.vehicles.{v.id}.initial.position_enu_m.{k}"]
            assert abs(moved - v.initial.position_enu_m[k]) <= 0.5


def test_shared_draws_one_value_and_around_slot_scatters_about_the_formation(tmp_path):
    study = load_study(write_study(tmp_path, """\
        parameters:
          - key: vehicles[*].plant.mass_kg
            scale: {log_uniform: [0.5, 2.0]}
            per: shared
          - key: vehicles[*].initial.position_enu_m
            add: {normal: [0.0, 0.1]}
            each: component
            around_slot: [0.0, 0.0, 10.0]
        """))
    team, params = study.team(0)
    base = load_team(CONFIGS / "square4.yaml")
    factors = {params[f"param.vehicles.{v.id}.plant.mass_kg"] / v.plant.mass_kg
               for v in base.vehicles}
    # THEN one factor for all four vehicles
    assert max(factors) - min(factors) < 1e-12
    # AND each vehicle starts within 1 m (10 sigma) of its slot 10 m up
    for v in team.vehicles:
        slot = np.array(v.offset_enu_m) + [0.0, 0.0, 10.0]
        assert np.linalg.norm(np.array(v.initial.position_enu_m) - slot) < 1.0


def test_a_batch_flies_each_team_to_the_same_bits_as_flying_it_alone(tmp_path):
    # GIVEN three different teams of one study
    study = load_study(write_study(tmp_path, SMALL))
    teams = [study.team(k)[0] for k in range(3)]
    options = SimOptions(log_rate_hz=50.0)
    # WHEN flown as one batch and one by one
    together = simulate_batch(teams, options)
    alone = [simulate(t, options) for t in teams]
    # THEN every logged number is equal
    for a, b in zip(together, alone, strict=True):
        for name in ("position_enu_m", "velocity_enu_mps", "mass_estimate_kg", "force_enu_n",
                     "attitude_error"):
            assert np.array_equal(getattr(a.log, name), getattr(b.log, name)), name
    # AND the teams did differ (a batch that mixed them up could not pass)
    assert not np.array_equal(together[0].log.position_enu_m, together[1].log.position_enu_m)


def test_a_row_does_not_depend_on_the_runs_that_shared_its_batch(tmp_path):
    study = load_study(write_study(tmp_path, SMALL))
    # WHEN run 5 is flown with 0..7 and alone
    with_others = fly_runs(study, list(range(8)))[5]
    alone = fly_runs(study, [5])[0]
    # THEN its rows are equal, NaN for NaN
    assert with_others.keys() == alone.keys()
    for k, v in alone.items():
        w = with_others[k]
        assert v == w or (isinstance(v, float) and math.isnan(v) and math.isnan(w)), k
    assert list(alone)[:4] == ["run", "seed", "status", "message"]
    assert list(alone)[-len(METRICS):] == list(METRICS)


def _still_log(positions: np.ndarray, offsets: np.ndarray) -> FlightLog:
    k, n = positions.shape[:2]
    zeros = np.zeros((k, n))
    return FlightLog(
        t_s=np.arange(k) * 1.0, position_enu_m=positions, velocity_enu_mps=np.zeros((k, n, 3)),
        reference_velocity_enu_mps=np.zeros((k, 3)), attitude_error=zeros,
        omega_error_radps=zeros, mass_estimate_kg=np.ones((k, n)) * 1.1,
        mass_true_kg=np.ones((k, n)), inertia_estimate_kgm2=np.ones((k, n, 3)),
        thrust_n=np.ones((k, n)), force_enu_n=np.tile([0.0, 0.0, 9.0], (k, n, 1)),
        vehicle_ids=np.arange(1, n + 1), sysids=np.arange(1, n + 1), offsets_enu_m=offsets,
        source="sim", controller="adaptive", team="t", name="t", extra={})


def test_the_row_of_a_known_flight(tmp_path):
    # GIVEN four vehicles 1 m off their square for 3 s, then on it for 3 s, static
    team = load_team(CONFIGS / "square4.yaml")
    offsets = np.array(team.offsets_enu_m())
    positions = np.repeat(offsets[None], 6, axis=0).copy()
    positions[:3, 0, 0] += 1.0
    row = run_row(_still_log(positions, offsets), team, StudyMetrics(4.0, 0.01, 1.0))
    # THEN it converged at 3 s with zero error after; the mass 10 % high; nearest pair 4 m
    assert row["converged"] and row["converge_time_s"] == 3.0
    assert row["final_error_m"] == 0.0 and row["max_error_m"] == 0.0
    assert row["mass_error_pct"] == pytest.approx(10.0)
    assert row["min_distance_m"] == pytest.approx(4.0)
    # AND while off, s = c_p * 1 m = 4 >= sigma_a on the vehicle and its two neighbours:
    # 3 vehicles x 3 samples of 4 x 6
    assert row["saturation_share"] == pytest.approx(9 / 24)
    assert row["cond.uz_positive"] and row["min_force_up_n"] == 9.0
    # AND a vehicle 2 m from another counts as 2 m
    positions[:, 1] = positions[:, 0] + [0.0, 2.0, 0.0]
    assert min_distance_m(positions) == pytest.approx(2.0)


def test_the_store_resumes_and_refuses_another_study(tmp_path):
    study = load_study(write_study(tmp_path, SMALL))
    store = ResultStore(tmp_path / "out", study)
    assert store.open() == set()
    store.add(fly_runs(study, [0, 1, 2]))
    # WHEN reopened THEN it knows runs 0..2
    assert ResultStore(tmp_path / "out", study).open() == {0, 1, 2}
    assert batches([5, 3, 4, 9], 3) == [[3, 4, 5], [9]]
    # AND another study (one number changed) is refused there
    other = load_study(write_study(tmp_path, SMALL.replace("0.8, 1.0", "0.7, 1.0"), "o.yaml"))
    with pytest.raises(ConfigError, match="holds the results of another study"):
        ResultStore(tmp_path / "out", other).open()


def test_a_heat_map_axis_must_be_a_parameter_column(tmp_path):
    path = write_study(tmp_path, SMALL + "metrics:\n  heatmap: [vehicles.1.plant.mass_kg, "
                       "vehicles.1.plant.mass]\n")
    with pytest.raises(ConfigError, match=r"metrics.heatmap\[1\]: 'vehicles.1.plant.mass' is no "
                                          "parameter column of this study"):
        load_study(path)
    ok = load_study(write_study(tmp_path, SMALL + "metrics:\n  heatmap: [vehicles.1.plant.mass_kg,"
                                " vehicles.2.initial.position_enu_m.0]\n", "ok.yaml"))
    assert ok.metrics.heatmap == ("vehicles.1.plant.mass_kg", "vehicles.2.initial.position_enu_m.0")


def test_a_drawn_team_that_is_not_valid_is_an_error_row_and_the_others_fly(tmp_path):
    # GIVEN vehicle 3 (4 x 3 N of thrust) drawn at 2.5-3.5x its 0.35 kg: from 2.91x it cannot
    # lift 1.2 m g, so some runs are refused and the others fly
    study = load_study(write_study(tmp_path, SMALL.replace(
        "  - key: vehicles[*].plant.mass_kg\n    scale: {uniform: [0.8, 1.0]}\n",
        "  - key: vehicles[3].plant.mass_kg\n    scale: {uniform: [2.5, 3.5]}\n")))
    rows = fly_runs(study, list(range(8)))
    refused = [r for r in rows if r["status"] == "error"]
    flown = [r for r in rows if r["status"] == "ok"]
    assert refused and flown
    for r in refused:
        assert r["param.vehicles.3.plant.mass_kg"] > 2.9 * 0.35
        assert "rotor_thrust_max_n" in r["message"] and math.isnan(r["final_error_m"])
    for r in flown:
        assert r["param.vehicles.3.plant.mass_kg"] < 2.92 * 0.35
        assert math.isfinite(r["final_error_m"])
