"""The px4 and ardupilot personalities against the recorded SITL flights (../shared/data/sitl).

Each personality replays its recording's setpoint stream (vehicle_emulator/calibration/replay.py: in-process,
simulated time, pymavlink-encoded setpoints, the recorded GCS's altitude law closed on the decoded
telemetry) into N_VEHICLES vehicles, whose noise streams differ, and the emulated figures (means
over vehicles and repetitions) are compared with the recorded ones read from the JSON summaries:
per axis the 63 % rise time within 25 % and the peak rate within 20 %, every hover noise std
(IMU, reported rates, detrended attitude and local position) within a factor 1.5, the thrust
steps' gain within 15 % and lag within 25 %, and the position samples' age.
`benchmarks/calibration/fit_emulator.py` prints the whole table.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from vehicle_emulator.calibration import replay as rp

N_VEHICLES = 8
SEED = 0
T63_TOL, PEAK_TOL, NOISE_FACTOR = 0.25, 0.20, 1.5
THRUST_GAIN_TOL, THRUST_LAG_TOL = 0.15, 0.25
NOISE_KEYS = (
    [f"HIGHRES_IMU.{f}" for f in rp.IMU_FIELDS]
    + [f"ATTITUDE_QUATERNION.{f}" for f in rp.AQ_FIELDS]
    + [f"attitude.{a}" for a in rp.AXES]
    + [f"LOCAL_POSITION_NED.{f}" for f in rp.LPN_FIELDS]
)
@pytest.fixture(scope="module", params=["px4", "ardupilot"])
def figures(request):
    """(autopilot, recorded figures, emulated figures) of one full replay."""
    try:
        rec = rp.load_recording(request.param)
    except FileNotFoundError as exc:  # no data: fail, do not skip (the README's data is ours)
        pytest.fail(str(exc))
    traces = rp.replay(rec, n=N_VEHICLES, seed=SEED)
    return request.param, rp.recorded_figures(rec), rp.emulated_figures(traces, rec)


def _ratio(figures, key):
    _, recorded, emulated = figures
    r, e = recorded[key], emulated[key]
    assert r is not None and e is not None, f"{key}: recorded {r}, emulated {e}"
    return e / r


@pytest.mark.parametrize("axis", rp.AXES)
def test_rate_doublets_rise_and_peak_like_the_recording(figures, axis):
    autopilot, recorded, emulated = figures
    # THEN the 63 % rise time within 25 % and the peak within 20 % of the recorded ones
    t63 = _ratio(figures, f"{axis}.t63_ms")
    peak = _ratio(figures, f"{axis}.peak")
    assert abs(t63 - 1) <= T63_TOL, (
        f"{autopilot} {axis}: t63 {emulated[f'{axis}.t63_ms']:.1f} ms, recorded "
        f"{recorded[f'{axis}.t63_ms']:.1f} ms")
    assert abs(peak - 1) <= PEAK_TOL, (
        f"{autopilot} {axis}: peak {emulated[f'{axis}.peak']:.3f}, recorded "
        f"{recorded[f'{axis}.peak']:.3f} rad/s")
    # and the 90 % level is reached exactly when the recording reached it (PX4's yaw does not:
    # its authority ends short of the command within the 0.6 s)
    assert (emulated[f"{axis}.t90_ms"] is None) == (recorded[f"{axis}.t90_ms"] is None)


def test_hover_noise_stds_match_the_recording_within_a_factor(figures):
    autopilot, recorded, emulated = figures
    off = []
    for key in NOISE_KEYS:
        ratio = _ratio(figures, key)
        if not 1 / NOISE_FACTOR <= ratio <= NOISE_FACTOR:
            off.append(f"{key}: recorded {recorded[key]:.3g}, emulated {emulated[key]:.3g} "
                       f"({ratio:.2f}x)")
    assert not off, f"{autopilot}: " + "; ".join(off)


# Fast-mixing signals (IMU, reported rates, attitude) hold the factor whatever the noise seed;
# the detrended local position is one 20 s stretch of a random walk (the GCS holds only the
# altitude), whose mean over 8 vehicles spreads 0.5-1.8x over seeds (docs/emulator.md).
SEED_STABLE_KEYS = [k for k in NOISE_KEYS if not k.startswith("LOCAL_POSITION_NED.")]


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
@pytest.mark.parametrize("seed", [1, 2])
def test_hover_attitude_and_imu_noise_hold_the_factor_for_other_seeds(autopilot, seed):
    rec = rp.load_recording(autopilot)
    recorded = rp.recorded_figures(rec)
    traces = rp.replay(rec, n=N_VEHICLES, seed=seed, until_s=rec.hover_window_s[1] + 0.05)
    emulated = rp.emulated_figures(traces, rec, parts=("hover",))
    off = [f"{k}: {emulated[k] / recorded[k]:.2f}x" for k in SEED_STABLE_KEYS
           if not 1 / NOISE_FACTOR <= emulated[k] / recorded[k] <= NOISE_FACTOR]
    assert not off, f"{autopilot} seed {seed}: " + "; ".join(off)


def test_thrust_steps_gain_and_lag_like_the_recording(figures):
    autopilot, recorded, emulated = figures
    # THEN the pooled first-order fit's gain within 15 % and its lag (dead time + time constant)
    # within 25 %; the per-edge gains scatter by +-25 % on the recording itself (drag, state)
    assert abs(_ratio(figures, "thrust.fit_gain") - 1) <= THRUST_GAIN_TOL
    lag_rec = recorded["thrust.dead_time_ms"] + recorded["thrust.tau_ms"]
    assert abs(emulated["thrust.lag_ms"] / lag_rec - 1) <= THRUST_LAG_TOL, (
        f"{autopilot}: lag {emulated['thrust.lag_ms']:.1f} ms, recorded {lag_rec:.1f} ms")


def test_position_samples_are_as_much_older_than_attitude_as_recorded(figures):
    autopilot, recorded, emulated = figures
    # PX4: LOCAL_POSITION_NED 4 ms older than ATTITUDE_QUATERNION; ArduPilot: the same age
    assert emulated["timing.position_age_ms"] == pytest.approx(
        recorded["timing.position_age_ms"], abs=1.5)


def test_the_comparison_fails_for_a_model_that_is_not_the_autopilot():
    # GIVEN the nominal model (stiff, noise-free loops) on PX4's SIH airframe, replayed through
    # PX4's recording up to its first yaw doublet
    rec = rp.load_recording("px4")
    specs = [replace(s, autopilot="nominal") for s in rp.sitl_airframe("px4", 1, rec.law["h_ref"])]
    yaw = next(d for d in rec.doublets if d.axis == 2)
    traces = rp.replay(rec, n=1, specs=specs, until_s=yaw.edges_s[2] + 0.3)
    emulated = rp.emulated_figures(traces, rec, parts=("rates", "hover"))
    recorded = rp.recorded_figures(rec)
    # THEN the yaw rise and the gyro noise are far outside the tolerances the tests apply
    assert emulated["yaw.t63_ms"] < (1 - T63_TOL) * recorded["yaw.t63_ms"]
    assert emulated["HIGHRES_IMU.xgyro"] < recorded["HIGHRES_IMU.xgyro"] / NOISE_FACTOR
