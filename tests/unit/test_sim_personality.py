"""gcs sim's `sim.autopilot` airframes against the emulator's personalities of the same name:
the linear drag's size, and a coasting vehicle slowing down as the personality's plant does."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from flightkit.physics import GRAVITY_MPS2
from gcs.sim.autopilot import LINEAR_DRAG_PER_S, linear_drag_per_s
from gcs.sim.loop import plant_step
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
