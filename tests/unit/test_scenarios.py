"""The paper's Section V scenarios in-process: the verification mode against the reference figures
of the corrected equations (docs/reproducing-the-paper.md quotes them beside ours), and the
implementable default (model-based derivatives, sampled law at 1 kHz) against the acceptance
bounds."""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from gcs import metrics
from gcs.config import load_team
from gcs.sim.runner import SimOptions, simulate

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
Z_SHIFT_M = 10.0  # our configs start the paper's scenario 10 m higher

pytestmark = pytest.mark.slow


@cache
def run(config: str, **options):
    return simulate(load_team(CONFIGS / config), SimOptions(**options)).log


def at(log, t_s: float) -> int:
    k = int(np.argmin(np.abs(log.t_s - t_s)))
    assert abs(log.t_s[k] - t_s) < 1e-9, f"no log sample at t = {t_s}"
    return k


def formation_error(log) -> np.ndarray:
    return metrics.formation_error(log.position_enu_m, log.offsets_enu_m)


def velocity_error(log) -> np.ndarray:
    return metrics.velocity_error(log.velocity_enu_mps, log.reference_velocity_enu_mps)


# Spec 4.1: formation error, velocity error (exact derivatives).
REFERENCE_4_1 = {
    5: (3.14e-2, 5.59e-2),
    10: (1.07e-5, 7.4e-6),
    20: (1.02e-5, 7.0e-6),
    30: (3.6e-6, 5.5e-6),
    60: (9.4e-6, 7.1e-6),
}
REFERENCE_MASS = {
    1: (0.7741, 1.4322, 0.3827, 3.0964),
    2: (0.8305, 1.2546, 0.3602, 3.3282),
    5: (0.84964, 1.20091, 0.35043, 3.39500),
    10: (0.85, 1.2, 0.35, 3.4),
}
REFERENCE_JHAT_60 = (
    (0.0535, 0.0587, 0.0801),
    (0.1483, 0.1160, 0.0806),
    (0.1244, 0.1024, 0.0798),
    (0.1238, 0.1472, 0.0807),
)


def test_verification_mode_reproduces_the_scenario_i_reference_table():
    # GIVEN Scenario I run with the law inside every RK4 stage and the exact u', u''
    log = run("square4.yaml", oracle=True)
    fe, ve = formation_error(log), velocity_error(log)
    # THEN formation and velocity errors match spec 4.1 within 2 % of each value (the table
    # gives two or three digits, 3.6e-6 to 5.59e-2; the simulation lands within 0.8 % of all)
    for t, (fe_ref, ve_ref) in REFERENCE_4_1.items():
        assert fe[at(log, t)] == pytest.approx(fe_ref, rel=0.02), t
        assert ve[at(log, t)] == pytest.approx(ve_ref, rel=0.02), t
    assert fe[at(log, 0)] == pytest.approx(7.07, abs=5e-3)
    # AND the mass estimates alpha_m mhat/phi match the reference within 1e-3 kg
    for t, masses in REFERENCE_MASS.items():
        np.testing.assert_allclose(log.mass_estimate_kg[at(log, t)], masses, atol=1e-3)
    # AND Jhat stays bounded at the reference values (no persistent excitation, spec 4.1)
    np.testing.assert_allclose(log.inertia_estimate_kgm2[-1], REFERENCE_JHAT_60, atol=1e-3)
    # AND the largest attitude errors are at t = 0 (R(0) = I, tilted R^c(0))
    np.testing.assert_allclose(
        log.attitude_error.max(axis=0), (0.026, 0.118, 0.173, 0.026), atol=1e-3
    )


REFERENCE_5_ADAPTIVE_Z = {40: -0.1903, 45: -0.0232, 50: -0.0231, 60: -0.0231, 80: -0.0231}
REFERENCE_5_BASELINE_Z = {
    40: (0.1811,) * 4,
    45: (2.7309, 2.3456, 2.2172, 2.3456),
    50: (5.3006, 4.9151, 4.7866, 4.9151),
    60: (10.4398, 10.0544, 9.9259, 10.0544),
    80: (20.7184, 20.3330, 20.2045, 20.3330),
}
REFERENCE_5_UAV1_MASS = {40.5: 0.710, 41: 0.648, 42: 0.604, 45: 0.595}


def test_verification_mode_reproduces_the_scenario_ii_tables():
    # GIVEN Scenario II (UAV 1 loses 30 % of its mass at 40 s) in the verification mode
    adaptive = run("square4_massdrop.yaml", oracle=True)
    baseline = run("square4_massdrop.yaml", oracle=True, law="baseline")
    # THEN the adaptive team re-forms on a plane 0.167 m higher (spec 5) within 1e-3 m
    for t, z in REFERENCE_5_ADAPTIVE_Z.items():
        np.testing.assert_allclose(
            adaptive.position_enu_m[at(adaptive, t), :, 2] - Z_SHIFT_M, z, atol=1e-3
        )
    for t, m1 in REFERENCE_5_UAV1_MASS.items():
        assert adaptive.mass_estimate_kg[at(adaptive, t), 0] == pytest.approx(m1, abs=1e-3)
    assert formation_error(adaptive)[at(adaptive, 80)] < 1e-4
    # AND the baseline climbs at 0.514 m/s with UAV 1 0.385 m above the others
    for t, z in REFERENCE_5_BASELINE_Z.items():
        np.testing.assert_allclose(
            baseline.position_enu_m[at(baseline, t), :, 2] - Z_SHIFT_M, z, atol=1e-3
        )
    np.testing.assert_allclose(baseline.velocity_enu_mps[at(baseline, 60), :, 2], 0.5139, atol=1e-3)


def test_default_sim_meets_the_scenario_i_acceptance_bounds():
    # GIVEN the implementable law: model-based u', u'', sampled at 1 kHz, zero-order hold
    log = run("square4.yaml")
    fe, ve = formation_error(log), velocity_error(log)
    # THEN the formation converges and the masses are identified
    assert fe[at(log, 5)] <= 0.1
    assert fe[at(log, 20)] <= 1e-3 and fe[at(log, 60)] <= 1e-3
    assert ve[at(log, 60)] <= 1e-3
    np.testing.assert_allclose(
        log.mass_estimate_kg[at(log, 10)], log.mass_true_kg[at(log, 10)], atol=1e-3
    )
    # AND the command force keeps u_z > 0 (the condition of (14))
    assert log.force_enu_n[..., 2].min() > 0.0


def test_default_sim_meets_the_scenario_ii_acceptance_bounds():
    adaptive = run("square4_massdrop.yaml")
    baseline = run("square4_massdrop.yaml", law="baseline")
    late = adaptive.t_s >= 50.0
    # THEN the adaptive team stops climbing after the drop and stays in formation
    assert np.abs(adaptive.velocity_enu_mps[late, :, 2]).max() <= 0.01
    assert formation_error(adaptive)[at(adaptive, 60)] <= 0.01
    # AND the baseline keeps climbing
    assert np.abs(baseline.velocity_enu_mps[at(baseline, 60), :, 2]).min() >= 0.4
    gained = (
        baseline.position_enu_m[at(baseline, 80), :, 2]
        - baseline.position_enu_m[at(baseline, 40), :, 2]
    )
    assert gained.min() >= 15.0


def test_mass_estimator_error_obeys_eq_37_along_the_closed_loop():
    # GIVEN the verification run of Scenario I, with mt = alpha_m mhat - phi m = phi (kappa - m)
    log = run("square4.yaml", oracle=True)
    sig = 1.0
    v = log.velocity_enu_mps
    phi = 2.0 + np.tanh(v / sig).sum(axis=2) * sig / (3.0 * sig)
    mt = phi * (log.mass_estimate_kg - log.mass_true_kg)
    # WHEN (37), mt' = -g dsat(v_z)/(3 sigma phi) mt, is integrated along the logged velocities
    rate = -9.81 * (1.0 - np.tanh(v[:, :, 2] / sig) ** 2) / (3.0 * sig * phi)
    dt = np.diff(log.t_s)[:, None]
    integral = np.vstack([np.zeros((1, 4)), np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt, axis=0)])
    predicted = mt[0] * np.exp(integral)
    # THEN the estimator error follows it (to the trapezoid error of the 10 ms log)
    early = log.t_s <= 10.0
    np.testing.assert_allclose(mt[early], predicted[early], atol=2e-4 * np.abs(mt[0]).max())


def test_levant_differentiator_and_rates_mode_also_converge():
    # GIVEN the paper's differentiator (L = 1e4, 1e-4 s substeps) instead of the model
    levant = run("square4.yaml", derivative="levant", duration_s=30.0)
    # THEN the formation settles to the spec's Levant floor (3.4e-4 m with 1e-4 s substeps)
    assert formation_error(levant)[at(levant, 30)] < 1e-3
    # GIVEN the thrust + body-rate variant with an idealised autopilot rate loop
    rates = run("square4.yaml", mode="rates", duration_s=30.0)
    assert formation_error(rates)[at(rates, 30)] < 1e-3
    np.testing.assert_allclose(
        rates.mass_estimate_kg[at(rates, 20)], rates.mass_true_kg[0], atol=1e-3
    )


def test_slower_controller_rates_still_fly():
    # GIVEN the law sampled at 250 Hz (torque held 4 ms) WHEN run THEN it still converges in
    # rates mode, whose rate loop runs at the plant rate (spec section 9)
    log = run("square4.yaml", mode="rates", controller_rate_hz=250.0, duration_s=30.0)
    assert formation_error(log)[at(log, 30)] < 5e-3


def _actuators_mode_run(alpha_rho: float):
    """Scenario I as `gcs fly --mode actuators` ticks it (250 Hz, the flown torque gains)."""
    team = load_team(CONFIGS / "square4.yaml")
    flown = team.fly.actuators
    gains = team.controller.gains._replace(
        alpha_eps=flown.alpha_eps, alpha_omega=flown.alpha_omega, alpha_rho=alpha_rho)
    team = dataclasses.replace(team, controller=dataclasses.replace(team.controller, gains=gains))
    return simulate(team, SimOptions(mode="actuators", controller_rate_hz=250.0,
                                     duration_s=20.0)).log


def test_actuators_mode_gains_fly_the_paper_formation_with_the_papers_inertia_excursion():
    # GIVEN the torque gains actuators mode flies at 250 Hz ((2, 2), alpha_rho 0.03)
    flown = _actuators_mode_run(load_team(CONFIGS / "square4.yaml").fly.actuators.alpha_rho)
    # THEN the formation is the paper's, and Jhat stays positive and within twice the paper's
    # largest (its own loop: 0.148 at 60 s)
    assert formation_error(flown)[at(flown, 20)] < 1e-3
    assert np.all(flown.inertia_estimate_kgm2 > 0.0)
    assert np.max(flown.inertia_estimate_kgm2) < 2.0 * float(np.max(REFERENCE_JHAT_60))
