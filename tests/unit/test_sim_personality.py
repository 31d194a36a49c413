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
from gcs.sim.noise import NOISE_MODELS, PX4_NOISE, add_telemetry_errors, make_noise, noise_draws
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
