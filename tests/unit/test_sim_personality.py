"""gcs sim's `sim.autopilot` against the emulator's personalities of the same name: the linear
drag (its size, a coasting vehicle slowing down as the personality's plant does) and the
acceleration the law reads (the accelerometer turned by the reported attitude, its noise)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from flightkit.physics import GRAVITY_MPS2
from gcs.sim.autopilot import LINEAR_DRAG_PER_S, linear_drag_per_s
from gcs.sim.loop import plant_step
from gcs.sim.noise import (
    ARDUPILOT_NOISE,
    NOISE_MODELS,
    PX4_NOISE,
    add_telemetry_errors,
    make_noise,
    noise_draws,
    recorded_position,
)
from vehicle_emulator.config.personality import personality_of
from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.physics.plant import ControlMode, FleetPlant


@pytest.mark.parametrize("autopilot", sorted(LINEAR_DRAG_PER_S))
def test_each_autopilots_drag_is_its_personalitys(autopilot):
    # the personality is the source of truth: px4 SIH_KDV 1 N/(m/s) on 1 kg, the others none
    assert linear_drag_per_s(autopilot) == personality_of(autopilot).dynamics.linear_drag_per_s
    assert linear_drag_per_s("ideal") == 0.0


def _coast_in_sim(drag_per_s: float, v0, seconds: float, dt_s: float = 1e-3):
    """Velocity of one level vehicle at hover thrust, no torque, after `seconds` of gcs sim's
    plant steps."""
    p, v = np.array([[0.0, 0.0, 10.0]]), np.array([v0], dtype=float)
    rot, w = np.eye(3)[None].copy(), np.zeros((1, 3))
    mass, inertia = np.array([1.0]), np.array([[0.025, 0.025, 0.03]])
    thrust, torque = mass * GRAVITY_MPS2, np.zeros((1, 3))
    for _ in range(int(round(seconds / dt_s))):
        plant_step(p, v, rot, w, thrust, torque, mass, inertia, np.array([drag_per_s]), dt_s)
    return v[0]


def test_drag_decelerates_a_coasting_vehicle_at_the_personalitys_rate():
    # GIVEN a level vehicle moving at 1 m/s east, 0.5 m/s north, hover thrust, no torque
    # WHEN gcs sim's plant coasts it for 2 s with px4's drag, and with ideal's
    v_px4 = _coast_in_sim(linear_drag_per_s("px4"), (1.0, 0.5, 0.0), 2.0)
    v_ideal = _coast_in_sim(linear_drag_per_s("ideal"), (1.0, 0.5, 0.0), 2.0)
    # THEN px4's velocity decays as exp(-k t) with SIH_KDV / SIH_MASS = 1 /s, ideal's not at all
    assert v_px4 == pytest.approx(np.array([1.0, 0.5, 0.0]) * np.exp(-2.0), abs=1e-9)
    assert v_ideal == pytest.approx([1.0, 0.5, 0.0], abs=1e-12)


def test_a_coasting_px4_vehicle_slows_as_the_personalitys_plant():
    # GIVEN the px4 personality's plant with one vehicle in the air moving east at 2 m/s, its
    # rotors off (only gravity and drag act: level, no horizontal thrust)
    spec = replace(default_vehicle(1, on_ground=False), autopilot="px4",
                   velocity_enu_mps=(2.0, 0.0, 0.0))
    plant = FleetPlant([spec])
    plant.mode[:] = ControlMode.OFF
    # WHEN both coast for 1 s
    plant.step(1000)
    v_sim = _coast_in_sim(linear_drag_per_s("px4"), (2.0, 0.0, 0.0), 1.0)
    # THEN the horizontal speeds agree: the same drag, applied the same way
    assert plant.velocity_enu_mps[0, 0] == pytest.approx(2.0 * np.exp(-1.0), rel=1e-9)
    assert v_sim[0] == pytest.approx(plant.velocity_enu_mps[0, 0], rel=1e-9)


def _hover_errors(model, ticks: int, seed: int = 3):
    """The reported attitude and the law's acceleration of one level vehicle hovering at rest
    (true acceleration zero) over `ticks` ticks of 10 ms with `model`'s telemetry errors."""
    noise = make_noise(model, ticks, 1, 0.01, noise_draws(seed, ticks, 1))
    p, v, w, acc = np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3))
    rot = np.eye(3)[None].copy()
    rots, accs = np.empty((ticks, 3, 3)), np.empty((ticks, 3))
    for k in range(ticks):
        _, _, rot_out, _, acc_out = add_telemetry_errors(noise, k, p, v, rot, w, acc,
                                                      GRAVITY_MPS2, 0.01)
        rots[k], accs[k] = rot_out[0], acc_out[0]
    return rots, accs


def test_the_law_reads_the_accelerometer_turned_by_the_reported_attitude():
    # GIVEN a level vehicle at rest whose reported attitude carries PX4's slow pitch error
    # (0.016 rad over 4 s) and no other error, no accelerometer noise
    only_pitch = PX4_NOISE._replace(
        gyro_std_radps=(0.0, 0.0, 0.0), tilt_std_rad=(0.0, 0.0, 0.0),
        attitude_std_rad=(0.0, 0.016, 0.0), velocity_std_mps=(0.0, 0.0, 0.0),
        drift_std_mps=(0.0, 0.0, 0.0), accel_std_mps2=(0.0, 0.0, 0.0))
    # WHEN the law reads it for 300 s
    rots, accs = _hover_errors(only_pitch, 30000)
    # THEN its acceleration is the specific force g e3 turned by the reported attitude, minus g
    # e3, as gcs fly computes it from HIGHRES_IMU and ATTITUDE_QUATERNION: g times the error,
    # east, where the vehicle does not accelerate at all
    assert accs == pytest.approx(GRAVITY_MPS2 * (rots[:, :, 2] - [0.0, 0.0, 1.0]), abs=1e-12)
    assert np.std(accs[:, 0]) == pytest.approx(GRAVITY_MPS2 * 0.016, rel=0.25)
    assert np.abs(accs[:, 1]).max() < 1e-12


@pytest.mark.parametrize("autopilot", sorted(NOISE_MODELS))
def test_the_accelerometer_noise_is_what_the_personality_reports(autopilot):
    # HIGHRES_IMU's accelerometer per personality: PX4 the mean of two raw samples, ArduCopter
    # its raw samples through the second-order low pass (noise bandwidth 1.11 f_c)
    sensors = personality_of(autopilot).sensors
    period_s = personality_of(autopilot).dynamics.control_period_s
    raw = np.array(sensors.accel_noise_std_mps2)
    if sensors.imu_filtered:
        expected = raw * math.sqrt(2.0 * 1.11 * sensors.accel_cutoff_hz * period_s)
    else:
        expected = raw / math.sqrt(sensors.imu_average_samples)
    assert NOISE_MODELS[autopilot].accel_std_mps2 == pytest.approx(expected, rel=1e-12)


def test_px4s_accelerometer_noise_has_its_size_in_the_law():
    # GIVEN PX4's accelerometer noise alone on a level vehicle at rest
    only_accel = PX4_NOISE._replace(
        gyro_std_radps=(0.0, 0.0, 0.0), tilt_std_rad=(0.0, 0.0, 0.0),
        attitude_std_rad=(0.0, 0.0, 0.0), velocity_std_mps=(0.0, 0.0, 0.0),
        drift_std_mps=(0.0, 0.0, 0.0))
    _, accs = _hover_errors(only_accel, 20000)
    # THEN the law's acceleration is white with SIH's 0.5 / 1.7 / 1.4 m/s^2 over sqrt(2)
    assert np.std(accs, axis=0) == pytest.approx(np.array([0.5, 1.7, 1.4]) / math.sqrt(2.0),
                                                 rel=0.03)
    assert abs(np.corrcoef(accs[1:, 1], accs[:-1, 1])[0, 1]) < 0.03


@pytest.mark.parametrize("autopilot", sorted(NOISE_MODELS))
def test_the_reported_position_integrates_the_personalitys_share_of_the_velocity_error(
        autopilot):
    # the personality is the source of truth: ArduCopter's EKF3 integrates all of its velocity
    # error into its position (forgotten over 3 s), PX4 SIH none of it
    sensors = personality_of(autopilot).sensors
    assert NOISE_MODELS[autopilot].position_share == sensors.velocity_error_in_position
    if sensors.velocity_error_in_position > 0.0:
        assert NOISE_MODELS[autopilot].position_tau_s == sensors.position_error_tau_s


def _hover_positions(model, ticks: int, seed: int = 5, v=(0.0, 0.0, 0.0)):
    """What the law reads and what the log records of one level vehicle moving at v over
    `ticks` ticks of 10 ms: (law position - truth, recorded position - truth, law velocity)."""
    noise = make_noise(model, ticks, 1, 0.01, noise_draws(seed, ticks, 1, model))
    p, w, acc = np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3))
    vel, rot = np.array([v], dtype=float), np.eye(3)[None].copy()
    law, rec, law_v = (np.empty((ticks, 3)) for _ in range(3))
    for k in range(ticks):
        p_out, v_out, _, _, _ = add_telemetry_errors(noise, k, p, vel, rot, w, acc,
                                                     GRAVITY_MPS2, 0.01)
        law[k], law_v[k] = p_out[0] - p[0], v_out[0]
        rec[k] = recorded_position(noise, k, p, vel)[0] - p[0]
        p = p + vel * 0.01
    return law, rec, law_v


def test_ardupilots_position_error_has_the_size_of_its_integrated_velocity_error():
    # GIVEN ArduCopter's telemetry errors on a vehicle at rest, no held samples
    model = ARDUPILOT_NOISE._replace(held_share=0.0)
    # WHEN the law reads its position for 600 s (120 of the velocity error's time constants)
    law, rec, law_v = _hover_positions(model, 60000)
    # THEN the error is the velocity error (1 sigma s, tau_v 5 s) integrated and forgotten over
    # tau_p 3 s: s tau_p sqrt(tau_v / (tau_v + tau_p)) per axis (north, east, up -> ENU)
    s = np.array(model.velocity_std_mps)[[1, 0, 2]]
    tv, tp = model.velocity_tau_s, model.position_tau_s
    assert np.std(law, axis=0) == pytest.approx(s * tp * math.sqrt(tv / (tv + tp)), rel=0.25)
    # AND the log records what the law reads, and the law's velocity (gcs fly's, corrected toward
    # the position's rate) still carries the error: the two estimates agree, so the correction
    # has nothing to remove
    assert rec == pytest.approx(law, abs=1e-15)
    assert np.std(law_v, axis=0) == pytest.approx(s, rel=0.3)


def test_px4s_position_carries_no_error():
    law, rec, _ = _hover_positions(PX4_NOISE, 2000)
    assert np.abs(law).max() == 0.0 and np.abs(rec).max() == 0.0


def test_a_held_record_is_the_previous_stream_periods_position():
    # GIVEN ArduCopter's errors without the estimate's, a vehicle flying east at 0.4 m/s
    model = ARDUPILOT_NOISE._replace(velocity_std_mps=(0.0, 0.0, 0.0))
    # WHEN gcs sim records it at 100 Hz for 200 s
    law, rec, _ = _hover_positions(model, 20000, v=(0.4, 0.0, 0.0))
    # THEN the law reads the truth, and the record is the truth or, in held_share of the
    # records, the position one stream period (10 ms) earlier: 4 mm behind
    assert np.abs(law).max() == 0.0
    held = rec[:, 0] < -1e-12
    assert rec[held, 0] == pytest.approx(-0.004, abs=1e-12)
    assert np.abs(rec[~held]).max() < 1e-12
    assert held.mean() == pytest.approx(model.held_share, abs=0.01)


#: The ardupilot personality flown by gcs fly on the 2026-12-04 ArduCopter SITL team file
#: (`vehicle-emu --fleet --team FILE --autopilot ardupilot --param GUID_OPTIONS=8`, one fleet
#: per flight; docs/benchmarks.md, "gcs sweep"): formation error for t >= 30 s, mean / max [m]
ARDUPILOT_PERSONALITY_M = ((0.0028, 0.0080), (0.0037, 0.0088), (0.0039, 0.0094))


def test_gcs_sim_on_ardupilot_flies_as_the_personality():
    # GIVEN the ArduCopter SITL team file with the rates gains it flew, in gcs sim on
    # sim.autopilot ardupilot (its loops, its position and velocity estimate errors, the records
    # gcs fly holds) at 100 Hz with 4 ms of link
    from pathlib import Path

    from gcs.config import load_team, team_from_dict, team_to_dict
    from gcs.metrics import formation_error
    from gcs.sim.runner import SimOptions, simulate

    data = team_to_dict(load_team(
        Path(__file__).parents[1] / "data" / "sitl" / "team_arducopter_sitl.yaml"))
    data["controller"]["mode"] = "rates"
    data["controller"]["gains"].update(alpha_p=1.0, c_p=2.0, k_eps=1.5, k_eps_yaw=1.0)
    figures = []
    for seed in (1, 2):
        data["sim"].update(controller_rate_hz=100, autopilot="ardupilot", link_seed=seed,
                           link_delay_s=0.004)
        # WHEN it flies Scenario I
        log = simulate(team_from_dict(data), SimOptions(log_rate_hz=50)).log
        e = formation_error(log.position_enu_m, log.offsets_enu_m)[log.t_s >= 30.0]
        figures.append((e.mean(), e.max()))
    # THEN its formation error for t >= 30 s is the personality's within 25 %, mean and max
    # (without the position error and the held records it was 0.0011 / 0.0021 m)
    sim_mean, sim_max = np.mean(figures, axis=0)
    flown_mean, flown_max = np.mean(ARDUPILOT_PERSONALITY_M, axis=0)
    assert sim_mean == pytest.approx(flown_mean, rel=0.25)
    assert sim_max == pytest.approx(flown_max, rel=0.25)
