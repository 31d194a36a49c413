"""FleetPlant: the emulator's layer over physics.py (inner loops, mixer, motor lag, faults,
ground plane), plus the physics acceptance points checked through the whole plant."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from flightkit.physics import GRAVITY_MPS2, rotors_from_wrench, wrench_from_rotors
from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.physics.plant import ControlMode, FleetPlant, torque_max_nm


def _plant(n=1, on_ground=False, **kw):
    # the nominal personality's plant (the paper's model; test_emulator_onboard.py covers the
    # calibrated ones)
    specs = [replace(default_vehicle(i + 1, on_ground=on_ground), autopilot="nominal")
             for i in range(n)]
    return FleetPlant(specs, **kw)


def test_hover_thrust_through_mixer_is_an_equilibrium():
    # GIVEN all four Table I vehicles in the air at hover thrust, zero rates (rates mode)
    p = _plant(4)
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    z0 = p.position_enu_m.copy()
    p.step(10_000)  # 10 s
    assert np.abs(p.position_enu_m - z0).max() < 1e-6
    assert np.allclose(p.rotor_thrust_n, (p.mass_kg * GRAVITY_MPS2 / 4)[:, None])


def test_free_fall_with_rotors_off_then_ground_contact():
    p = _plant(1)
    p.mode[:] = ControlMode.OFF
    p.step(1000)
    assert p.position_enu_m[0, 2] == pytest.approx(10.0 - 0.5 * GRAVITY_MPS2, abs=1e-9)
    assert p.velocity_enu_mps[0, 2] == pytest.approx(-GRAVITY_MPS2, abs=1e-9)
    p.step(2000)
    # lands: on the plane, at rest, level; the touchdown speed sqrt(2 g h) is recorded
    assert p.on_ground[0] and p.position_enu_m[0, 2] == 0.0
    assert np.all(p.velocity_enu_mps == 0.0) and np.allclose(p.rotation[0], np.eye(3))
    assert p.impact_speed_mps[0] == pytest.approx(math.sqrt(2 * GRAVITY_MPS2 * 10), rel=2e-3)
    assert p.specific_force_flu_mps2[0, 2] == GRAVITY_MPS2  # the ground carries the weight


def test_actuator_torque_gives_inverse_inertia_acceleration():
    p = _plant(1)
    p.mode[:] = ControlMode.ACTUATOR
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    p.torque_cmd_norm[0] = (0.1, -0.05, 0.02)
    p.step(1)
    tau = (
        np.array([0.1, -0.05, 0.02])
        * torque_max_nm(p.arm_length_m, p.anti_torque_m, p.rotor_thrust_max_n)[0]
    )
    assert np.allclose(p.torque_nm[0], tau)
    assert np.allclose(p.omega_flu_radps[0] / p.dt_s, tau / p.inertia_kgm2[0], rtol=1e-6)


def test_rotation_stays_orthonormal_over_60_s_of_rate_commands():
    p = _plant(2)
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = 0.9
    p.rate_cmd_flu_radps[:] = (1.0, -0.7, 0.4)
    p.step(60_000)
    for r in p.rotation:
        assert np.abs(r @ r.T - np.eye(3)).max() < 1e-9


def test_mixer_round_trip_and_rotor_limits():
    rng = np.random.default_rng(1)
    f = rng.uniform(0, 6.0, size=(100, 4))
    arm, anti, fmax = np.full(100, 0.2), np.full(100, 0.016), np.full(100, 6.0)
    t, tau = wrench_from_rotors(f, arm, anti)
    assert np.allclose(rotors_from_wrench(t, tau, arm, anti, fmax), f)
    f2 = rotors_from_wrench(t * 3, tau * 5, arm, anti, fmax)
    assert f2.min() >= 0.0 and f2.max() <= 6.0


def test_ground_holds_a_vehicle_below_hover_thrust_and_releases_it_above():
    p = _plant(1, on_ground=True)
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = 0.9 * p.hover_thrust_norm
    p.step(1000)
    assert p.on_ground[0] and p.position_enu_m[0, 2] == 0.0
    p.thrust_cmd_norm[:] = 1.2 * p.hover_thrust_norm
    p.step(1000)
    assert not p.on_ground[0]
    assert p.position_enu_m[0, 2] == pytest.approx(0.5 * 0.2 * GRAVITY_MPS2, rel=0.02)


def test_first_order_motor_lag():
    p = _plant(1, on_ground=True)
    p.motor_time_constant_s[:] = 0.05
    p.mode[:] = ControlMode.ACTUATOR
    p.thrust_cmd_norm[:] = 0.8
    p.step(50)  # one time constant
    target = 0.8 * p.rotor_thrust_max_n[0]
    assert p.rotor_thrust_n[0] == pytest.approx(target * (1 - math.exp(-1)), rel=1e-9)


def test_motor_efficiency_fault_unbalances_the_vehicle():
    # GIVEN rotor 1 (front, +x) at 50 % in rates mode THEN the rate loop holds attitude
    # roughly but the collective drops; in actuator mode the vehicle pitches about y
    p = _plant(1)
    p.mode[:] = ControlMode.ACTUATOR
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    p.rotor_efficiency[0, 0] = 0.5
    p.step(100)
    # f1 weaker: tau_y = d (f1 - f3) < 0 -> negative pitch rate (FLU)
    assert p.torque_nm[0, 1] < 0 and p.omega_flu_radps[0, 1] < 0


def test_mass_drop_changes_the_acceleration_at_the_step():
    p = _plant(1)
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    p.step(100)
    p.mass_kg[0] *= 0.7
    p.step(1)
    assert p.velocity_enu_mps[0, 2] / p.dt_s == pytest.approx(
        GRAVITY_MPS2 * (1 / 0.7 - 1), rel=1e-6
    )


def test_position_mode_takes_off_holds_and_lands_softly():
    p = _plant(1, on_ground=True)
    p.hold_here(0)
    p.position_sp_enu_m[0, 2] = 3.0
    p.step(8000)
    assert p.position_enu_m[0, 2] == pytest.approx(3.0, abs=0.05)
    p.position_mask[0, 2] = 0.0
    p.velocity_ff_enu_mps[0, 2] = -0.7
    p.step(8000)
    assert p.on_ground[0] and p.impact_speed_mps[0] < 0.8
