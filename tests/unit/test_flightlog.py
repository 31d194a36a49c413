"""FlightLog: validation, the per-sample builder, downsampling and the exact CSV round trip."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gcs.flightlog import FlightLog
from gcs.flightlog_builder import FlightLogBuilder
from gcs.flightlog_csv import CSV_HEADER, TIMESERIES_FORMAT, load_timeseries, save_timeseries

SERIES = (
    "t_s",
    "position_enu_m",
    "velocity_enu_mps",
    "reference_velocity_enu_mps",
    "attitude_error",
    "omega_error_radps",
    "mass_estimate_kg",
    "mass_true_kg",
    "inertia_estimate_kgm2",
    "thrust_n",
    "force_enu_n",
)
OFFSETS = np.array([[2.0, 2.0, 0.0], [2.0, -2.0, 0.0], [-2.0, -2.0, 0.0], [-2.0, 2.0, 0.0]])


def random_series(k: int, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "t_s": np.arange(k) / 100,
        "position_enu_m": rng.normal(size=(k, n, 3)),
        "velocity_enu_mps": rng.normal(size=(k, n, 3)),
        "reference_velocity_enu_mps": rng.normal(size=(k, 3)),
        "attitude_error": rng.uniform(0, 4, size=(k, n)),
        "omega_error_radps": rng.uniform(0, 1, size=(k, n)),
        "mass_estimate_kg": rng.uniform(0.3, 3, size=(k, n)),
        "mass_true_kg": rng.uniform(0.3, 3, size=(k, n)),
        "inertia_estimate_kgm2": rng.normal(0.08, 0.01, size=(k, n, 3)),
        "thrust_n": rng.uniform(0, 40, size=(k, n)),
        "force_enu_n": rng.normal(size=(k, n, 3)),
    }


def make_log(k: int = 11, n: int = 4, seed: int = 0, **overrides: object) -> FlightLog:
    kwargs: dict[str, object] = {
        **random_series(k, n, seed),
        "vehicle_ids": list(range(1, n + 1)),
        "sysids": list(range(11, n + 11)),
        "offsets_enu_m": OFFSETS[:n] if n <= 4 else np.zeros((n, 3)),
        "source": "sim",
        "controller": "adaptive",
        "team": "configs/square4.yaml",
        "name": "square4",
    }
    kwargs.update(overrides)
    return FlightLog.from_arrays(**kwargs)  # type: ignore[arg-type]


def assert_logs_equal(a: FlightLog, b: FlightLog, check_extra: bool = True) -> None:
    for name in SERIES:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        # bit-exact, NaN where NaN (array_equal with equal_nan also equates -0.0 and 0.0)
        assert np.array_equal(x, y, equal_nan=True), name
        real = ~np.isnan(x)  # a NaN's sign and payload carry no meaning and are not kept
        assert np.array_equal(np.signbit(x[real]), np.signbit(y[real])), name
    for name in ("vehicle_ids", "sysids", "offsets_enu_m"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("source", "controller", "team", "name"):
        assert getattr(a, name) == getattr(b, name), name
    if check_extra:
        assert a.extra == b.extra


# --------------------------------------------------------------------------------------------------
# Validation


def test_from_arrays_copies_to_readonly_float_arrays() -> None:
    # GIVEN lists and arrays WHEN a log is made THEN its arrays are read-only float64 copies
    series = random_series(5, 2)
    log = make_log(5, 2)
    assert log.n_samples == 5 and log.n_vehicles == 2
    assert log.position_enu_m.dtype == np.float64
    assert log.vehicle_ids.dtype == np.int64
    with pytest.raises(ValueError, match="read-only"):
        log.position_enu_m[0, 0, 0] = 1.0
    series["position_enu_m"][0, 0, 0] = 123.0  # the caller's array is not shared
    assert log.position_enu_m[0, 0, 0] != 123.0
    assert log.period_s == pytest.approx(0.01)
    assert log.vehicle_index(2) == 1


def test_unknown_true_mass_defaults_to_nan_and_constant_mass_broadcasts() -> None:
    log = make_log(4, 2, mass_true_kg=None)
    assert log.mass_true_kg.shape == (4, 2) and np.isnan(log.mass_true_kg).all()
    log = make_log(4, 2, mass_true_kg=[0.85, 1.2])
    assert np.array_equal(log.mass_true_kg, [[0.85, 1.2]] * 4)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"position_enu_m": np.zeros((11, 4, 2))}, r"position_enu_m: expected shape \(k, n, 3\)"),
        ({"thrust_n": np.zeros((10, 4))}, r"thrust_n: expected shape \(k, n\) = \(11, 4\)"),
        ({"reference_velocity_enu_mps": np.zeros((11, 4, 3))}, "reference_velocity_enu_mps"),
        ({"t_s": np.zeros(11)}, r"strictly increasing.*t_s\[1\] = 0.0"),
        ({"t_s": np.full(11, np.nan)}, "t_s: sample 0 is not finite"),
        ({"offsets_enu_m": np.zeros((3, 3))}, r"offsets_enu_m: expected shape \(4, 3\)"),
        ({"sysids": [1, 2, 3]}, r"sysids: expected shape \(4,\)"),
        ({"vehicle_ids": [1, 1, 2, 3]}, "expected unique ids"),
        ({"vehicle_ids": [1.5, 2, 3, 4], "sysids": [1, 2, 3, 4]}, "vehicle_ids: expected integers"),
        ({"source": "replay"}, r"source: expected one of \('sim', 'fly'\), got 'replay'"),
        ({"controller": "pid"}, "controller: expected one of"),
        ({"team": 3}, "team: expected str"),
    ],
)
def test_invalid_logs_raise_a_clear_error(override: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make_log(**override)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------------
# Builder


def test_builder_appends_samples_and_builds_the_same_log() -> None:
    # GIVEN a whole-array log WHEN it is fed sample by sample to a builder THEN build() equals it
    ref = make_log(7, 3, extra={"note": "x"})
    builder = FlightLogBuilder(
        vehicle_ids=[1, 2, 3],
        sysids=[11, 12, 13],
        offsets_enu_m=OFFSETS[:3],
        source="sim",
        controller="adaptive",
        team="configs/square4.yaml",
        name="square4",
        extra={"note": "x"},
    )
    for i in range(ref.n_samples):
        builder.append(
            t_s=ref.t_s[i],
            **{name: getattr(ref, name)[i] for name in SERIES[1:]},
        )
    assert len(builder) == 7
    assert_logs_equal(builder.build(), ref)
    # extra given to build() is merged over the builder's
    assert builder.build(extra={"link": {}}).extra == {"note": "x", "link": {}}


def test_builder_rejects_bad_samples_naming_the_field_and_sample() -> None:
    builder = FlightLogBuilder(
        vehicle_ids=[1, 2],
        offsets_enu_m=OFFSETS[:2],
        source="fly",
        controller="adaptive",
        team="t.yaml",
        name="r",
    )
    sample = {name: getattr(make_log(1, 2), name)[0] for name in SERIES[1:]}
    with pytest.raises(ValueError, match="no samples"):
        builder.build()
    builder.append(t_s=0.0, **{**sample, "mass_true_kg": None})
    with pytest.raises(
        ValueError, match=r"sample 1 \(t_s = 0.01\): thrust_n: expected shape \(n,\)"
    ):
        builder.append(t_s=0.01, **{**sample, "thrust_n": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match="sample 1: t_s = 0.0 is not after the previous"):
        builder.append(t_s=0.0, **sample)
    with pytest.raises(ValueError, match="not finite"):
        builder.append(t_s=math.inf, **sample)
    log = builder.build()
    assert log.n_samples == 1 and np.isnan(log.mass_true_kg).all()


def test_builder_validates_metadata_up_front() -> None:
    with pytest.raises(ValueError, match=r"offsets_enu_m: expected shape \(2, 3\)"):
        FlightLogBuilder(
            vehicle_ids=[1, 2],
            offsets_enu_m=np.zeros((3, 3)),
            source="fly",
            controller="adaptive",
            team="t.yaml",
            name="r",
        )


def test_downsample_keeps_multiples_of_the_period() -> None:
    # GIVEN a 1 kHz log of 2 s WHEN downsampled to 10 Hz THEN 21 samples at exact multiples of 0.1
    log = make_log(2001, 2, t_s=np.arange(2001) / 1000)
    small = log.downsample(0.1)
    assert small.n_samples == 21
    assert np.allclose(small.t_s, np.arange(21) / 10, rtol=0, atol=1e-12)
    assert np.array_equal(small.position_enu_m, log.position_enu_m[::100])


# --------------------------------------------------------------------------------------------------
# CSV


def test_csv_round_trip_is_exact(tmp_path: Path) -> None:
    # GIVEN a log with NaN (unknown true mass), -0.0, extreme floats and a per-run extra dict
    series = random_series(13, 4, seed=3)
    series["mass_true_kg"][5:, 2] = np.nan
    series["force_enu_n"][0, 0, 0] = -0.0
    series["thrust_n"][1, 1] = 5e-324
    series["position_enu_m"][2, 3, 1] = 1.7976931348623157e308
    series["t_s"] = series["t_s"] - 0.05  # pre-formation samples have t < 0
    extra = {"link": {"1": {"setpoints_sent": 10, "telemetry_lost_pct": 0.5}}, "nan": math.nan}
    log = make_log(13, 4, **series, extra=extra, team='configs/with, comma "quoted".yaml')
    # WHEN saved and loaded THEN every value comes back bit for bit
    path = save_timeseries(log, tmp_path / "run.csv")
    back = load_timeseries(path)
    assert_logs_equal(back, log, check_extra=False)  # NaN != NaN in the extra dict
    assert back.extra["link"] == extra["link"] and math.isnan(back.extra["nan"])
    assert not list(tmp_path.glob("*.tmp"))


def test_csv_layout_has_units_in_column_names_and_one_row_per_sample_and_vehicle(
    tmp_path: Path,
) -> None:
    log = make_log(3, 2)
    lines = save_timeseries(log, tmp_path / "run.csv").read_text().splitlines()
    assert lines[0] == f"# {TIMESERIES_FORMAT}"
    assert lines[1].startswith("# meta: {")
    assert lines[2].split(",") == list(CSV_HEADER)
    assert lines[2].startswith("t_s,vehicle_id,x_enu_m,y_enu_m,z_enu_m,vx_enu_mps")
    assert len(lines) == 3 + 3 * 2
    assert [row.split(",")[1] for row in lines[3:]] == ["1", "2"] * 3
    assert lines[4].split(",")[0] == "0.0"  # t_s written with repr


def test_load_accepts_reordered_rows_and_rejects_missing_ones(tmp_path: Path) -> None:
    log = make_log(5, 3)
    path = save_timeseries(log, tmp_path / "run.csv")
    lines = path.read_text().splitlines()
    head, body = lines[:3], lines[3:]
    # rows sorted by vehicle instead of by time load to the same log
    by_vehicle = sorted(body, key=lambda r: (int(r.split(",")[1]), float(r.split(",")[0])))
    path.write_text("\n".join(head + by_vehicle) + "\n")
    assert_logs_equal(load_timeseries(path), log)
    path.write_text("\n".join(head + body[:-1]) + "\n")
    with pytest.raises(ValueError, match=r"expected 5 samples x 3 vehicles = 15 rows, got 14"):
        load_timeseries(path)
    path.write_text("t_s,vehicle_id\n")
    with pytest.raises(ValueError, match="not a formation-flight-timeseries/1 file"):
        load_timeseries(path)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=25, deadline=None)
@given(
    positions=hnp.arrays(np.float64, (3, 2, 3), elements=finite),
    thrust=hnp.arrays(np.float64, (3, 2), elements=st.floats(width=64)),
    dt=st.floats(min_value=1e-6, max_value=10.0),
)
def test_csv_round_trip_property(
    tmp_path_factory: pytest.TempPathFactory, positions: np.ndarray, thrust: np.ndarray, dt: float
) -> None:
    # GIVEN arbitrary floats (thrust may be NaN or +-inf) WHEN round-tripped THEN unchanged
    path = tmp_path_factory.mktemp("csv") / "run.csv"
    log = make_log(3, 2, t_s=np.arange(3) * dt, position_enu_m=positions, thrust_n=thrust)
    assert_logs_equal(load_timeseries(save_timeseries(log, path)), log)
