"""TeamLaw (the fixed-tick law a ground station runs) against the compiled simulation loop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flightkit.physics import rk4_step
from gcs.config import load_team
from gcs.control.formation import reference_velocity
from gcs.control.geometry import rotation_from_rpy
from gcs.control.law import SingularCommandError, TeamLaw, TeamMeasurement
from gcs.sim.runner import SimOptions, law_gains, simulate

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "square4.yaml"


def fly_with_team_law(team, seconds, derivative="model", rate_hz=1000.0):
    """Closed loop written the way a ground station runs it: measure, TeamLaw.step, hold."""
    gains = law_gains(team)
    law = TeamLaw(
        gains,
        team.adjacency(),
        team.offsets_enu_m(),
        team.initial_mhat(),
        team.initial_inertia_estimates_kgm2(),
        derivative=derivative,
    )
    m, j = team.true_masses_kg(), team.true_inertias_kgm2()
    p = team.initial_positions_enu_m().copy()
    v = np.zeros((team.n, 3))
    rot = np.tile(np.eye(3), (team.n, 1, 1))
    w = np.zeros((team.n, 3))
    thrust = m * gains.gravity_mps2
    ref_args = team.reference_velocity.as_arrays()
    every = int(round(1000.0 / rate_hz))
    for step in range(int(seconds * 1000)):
        if step % every == 0:
            acc = thrust[:, None] * rot[:, :, 2] / m[:, None] - np.array([0, 0, gains.gravity_mps2])
            meas = TeamMeasurement(p.copy(), v.copy(), acc, rot.copy(), w.copy())
            cmd = law.step(meas, reference_velocity(step * 1e-3, *ref_args), every * 1e-3)
            thrust, torque = cmd.thrust_n, cmd.torque_nm
        rk4_step(p, v, rot, w, thrust, torque, m, j, 1e-3)
    return p, v, cmd


def test_team_law_reproduces_the_compiled_simulation():
    # GIVEN Scenario I flown for 2 s by TeamLaw in a Python loop and by gcs sim
    team = load_team(CONFIG)
    p, v, cmd = fly_with_team_law(team, 2.0)
    log = simulate(team, SimOptions(duration_s=2.0, log_rate_hz=1000.0)).log
    # THEN both implementations of the same discrete law agree to round-off: the last log row is
    # the state after 2000 steps, and the row before it holds the law output of the last tick
    np.testing.assert_allclose(log.position_enu_m[-1], p, atol=1e-9)
    np.testing.assert_allclose(log.mass_estimate_kg[-2], cmd.mass_estimate_kg, atol=1e-12)
    assert cmd.thrust_n.shape == (4,) and cmd.rate_cmd_radps.shape == (4, 3)


@pytest.mark.slow
def test_team_law_with_levant_at_1khz_converges():
    team = load_team(CONFIG)
    p, v, cmd = fly_with_team_law(team, 12.0, derivative="levant")
    offsets = team.offsets_enu_m()
    rel = (p - offsets) - (p - offsets).mean(axis=0)
    assert np.abs(rel).max() < 5e-3
    np.testing.assert_allclose(cmd.mass_estimate_kg, team.true_masses_kg(), atol=1e-3)


def test_singular_command_force_is_refused_with_the_vehicle_named():
    # GIVEN a team exactly in formation at v_r with a negative mass estimate state for vehicle 2,
    # so its command force points straight down
    team = load_team(CONFIG)
    mhat = team.initial_mhat().copy()
    mhat[2] = -1.0
    law = TeamLaw(
        law_gains(team),
        team.adjacency(),
        team.offsets_enu_m(),
        mhat,
        team.initial_inertia_estimates_kgm2(),
    )
    offsets = team.offsets_enu_m()
    ref = np.zeros((4, 3))
    meas = TeamMeasurement(
        offsets + 10.0,
        np.zeros((4, 3)),
        np.zeros((4, 3)),
        np.tile(np.eye(3), (4, 1, 1)),
        np.zeros((4, 3)),
    )
    # WHEN the law ticks THEN it refuses, naming the vehicle
    with pytest.raises(SingularCommandError, match="vehicle index 2"):
        law.step(meas, ref, 0.01)


def test_unknown_derivative_method_and_missing_nominal_masses_are_refused():
    team = load_team(CONFIG)
    args = (
        law_gains(team),
        team.adjacency(),
        team.offsets_enu_m(),
        team.initial_mhat(),
        team.initial_inertia_estimates_kgm2(),
    )
    with pytest.raises(ValueError, match="derivative method 'magic'"):
        TeamLaw(*args, derivative="magic")
    with pytest.raises(ValueError, match="baseline law needs nominal masses"):
        TeamLaw(*args, adaptive=False)


def test_adapt_false_holds_the_estimates():
    # GIVEN a law and one measurement WHEN stepped without adaptation THEN mhat and rhohat stay
    team = load_team(CONFIG)
    law = TeamLaw(law_gains(team), team.adjacency(), team.offsets_enu_m(), team.initial_mhat(),
                  team.initial_inertia_estimates_kgm2())
    meas = TeamMeasurement(team.initial_positions_enu_m(), np.zeros((4, 3)), np.zeros((4, 3)),
                           np.tile(np.eye(3), (4, 1, 1)), np.zeros((4, 3)))
    ref = np.zeros((4, 3))
    before = law.mhat.copy(), law.rhohat.copy()
    law.step(meas, ref, 0.01, adapt=False)
    np.testing.assert_array_equal(law.mhat, before[0])
    np.testing.assert_array_equal(law.rhohat, before[1])
    # AND WHEN stepped with adaptation THEN they move (the vehicles are out of formation)
    law.step(meas, ref, 0.01)
    assert np.abs(law.mhat - before[0]).max() > 0


def test_estimate_inertia_false_holds_rhohat_while_mhat_adapts():
    # GIVEN two laws on the same team, one told not to estimate the inertia (a flight whose
    # setpoint is not the torque (26)), and the vehicles out of formation, climbing
    team = load_team(CONFIG)
    args = (law_gains(team), team.adjacency(), team.offsets_enu_m(), team.initial_mhat(),
            team.initial_inertia_estimates_kgm2())
    held, used = TeamLaw(*args, estimate_inertia=False), TeamLaw(*args)
    rot = np.tile(rotation_from_rpy(0.1, -0.05, 0.2), (4, 1, 1))
    meas = TeamMeasurement(team.initial_positions_enu_m(), np.full((4, 3), 0.3), np.zeros((4, 3)),
                           rot, np.full((4, 3), 0.2))
    ref = reference_velocity(0.0, *team.reference_velocity.as_arrays())
    # WHEN both tick for 1 s at 100 Hz
    for _ in range(100):
        a, b = held.step(meas, ref, 0.01), used.step(meas, ref, 0.01)
    # THEN the held law's rhohat is still rhohat(0) and so is what it reports, while the other's
    # moved; the mass estimators, and the commands of this tick's state, are the same in both
    np.testing.assert_array_equal(held.rhohat, team.initial_inertia_estimates_kgm2())
    np.testing.assert_array_equal(a.inertia_estimate_kgm2, team.initial_inertia_estimates_kgm2())
    assert np.abs(used.rhohat - team.initial_inertia_estimates_kgm2()).max() > 1e-3
    np.testing.assert_array_equal(held.mhat, used.mhat)
    assert np.abs(held.mhat - team.initial_mhat()).max() > 1e-3
    np.testing.assert_array_equal(a.rate_cmd_radps, b.rate_cmd_radps)


def test_inertia_step_cap_advances_rhohat_by_one_tick_after_a_gap_and_mhat_by_the_gap():
    # GIVEN two laws on the same team, one capped at a 4 ms tick (gcs fly's), the vehicles out
    # of formation and turning (a state after a 100 ms stall on a held torque)
    team = load_team(CONFIG)
    args = (law_gains(team), team.adjacency(), team.offsets_enu_m(), team.initial_mhat(),
            team.initial_inertia_estimates_kgm2())
    capped, free = TeamLaw(*args), TeamLaw(*args)
    capped.inertia_step_max_s = 0.004
    rot = np.tile(rotation_from_rpy(0.1, -0.05, 0.2), (4, 1, 1))
    meas = TeamMeasurement(team.initial_positions_enu_m(), np.full((4, 3), 0.3), np.zeros((4, 3)),
                           rot, np.full((4, 3), 0.8))
    ref = reference_velocity(0.0, *team.reference_velocity.as_arrays())
    rho0 = team.initial_inertia_estimates_kgm2()
    # WHEN both step over a 100 ms gap
    capped.step(meas, ref, 0.1)
    free.step(meas, ref, 0.1)
    # THEN rhohat moved by a 4 ms step of the same rate, a 25th of the uncapped move; mhat, whose
    # I&I invariant needs the elapsed time, moved by the whole gap in both
    moved_free = free.rhohat - rho0
    assert np.abs(moved_free).max() > 1e-4
    np.testing.assert_allclose(capped.rhohat - rho0, moved_free / 25.0, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(capped.mhat, free.mhat)


@pytest.mark.parametrize(("mode", "estimated"), [("rates", False), ("actuators", True)])
def test_gcs_sim_integrates_the_inertia_estimate_only_where_the_torque_is_flown(mode, estimated):
    # GIVEN Scenario I simulated for 3 s in `mode`
    team = load_team(CONFIG)
    log = simulate(team, SimOptions(mode=mode, duration_s=3.0, log_rate_hz=100.0)).log
    j0 = team.initial_inertia_estimates_kgm2()
    # THEN rates mode (an autopilot rate loop makes the torque) keeps Jhat at Jhat(0) all along,
    # actuators mode (the torque (26) uses Jhat) adapts it; the record says which
    moved = np.abs(log.inertia_estimate_kgm2 - j0).max()
    assert (moved > 1e-3) if estimated else (moved == 0.0)
    assert log.extra["estimates"] == {"mass_from": ["team"] * 4, "inertia_from": "team",
                                      "inertia_kgm2": j0.tolist(), "inertia_estimated": estimated}
