"""gcs sim's link model (gcs/sim/link.py) and its attitude mode: what the law reads and when its
setpoints act, losses from the seed, and batches still equal to single runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.config import load_team, team_from_dict, team_to_dict
from gcs.metrics import formation_error
from gcs.sim.link import NOTHING, deliver, lost_masks, make_link, receive, record, send
from gcs.sim.runner import SimOptions, simulate, simulate_batch

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def team_with(**sim):
    data = team_to_dict(load_team(CONFIGS / "square4.yaml"))
    data["controller"]["mode"] = sim.pop("mode", "rates")
    data["controller"]["gains"].update(sim.pop("gains", {}))
    data["fly"]["predict"] = sim.pop("predict", True)
    data["mission"]["duration_s"] = sim.pop("duration_s", 30.0)
    data["sim"].update(controller_rate_hz=100, **sim)
    return team_from_dict(data)


def state(n: int, x: float):
    """Vehicle states whose every number is x (p, v, R, w), hovering (thrust m g), no drag."""
    return (np.full((n, 3), x), np.full((n, 3), x), np.full((n, 3, 3), x), np.full((n, 3), x),
            np.full(n, 9.81), np.ones(n), np.zeros(n), 9.81)


def test_the_law_reads_each_vehicle_d_steps_late_and_holds_a_lost_sample():
    # GIVEN two vehicles with delays 0 and 3 steps; vehicle 0's sample of tick 2 is lost
    lost_down = np.zeros((10, 2), dtype=bool)
    lost_down[2, 0] = True
    link = make_link(np.array([0, 3]), lost_down, np.zeros((10, 2), dtype=bool), False)
    assert link.active and link.taken_step[0] == NOTHING
    for step in range(6):
        record(link, step, *state(2, float(step)))
        # WHEN the law reads at steps 0, 2, 4 (ticks 0, 1, 2)
        if step % 2 == 0:
            p = receive(link, step, step // 2)[0]
            if step == 0:
                assert p[0, 0] == 0.0 and p[1, 0] == 0.0  # before t = 0: the initial hover
            if step == 2:
                assert p[0, 0] == 2.0 and p[1, 0] == 0.0
            if step == 4:
                # THEN vehicle 0's lost sample leaves it at step 2's, vehicle 1 reads step 1's
                assert p[0, 0] == 2.0 and p[1, 0] == 1.0
                assert list(link.taken_step) == [2, 1]


def test_a_setpoint_acts_d_steps_after_its_tick_unless_lost():
    lost_up = np.zeros((4, 2), dtype=bool)
    lost_up[1, 1] = True
    link = make_link(np.array([2, 2]), np.zeros((4, 2), dtype=bool), lost_up, False)
    thrust, rate, torque, rc = np.zeros(2), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3, 3))
    acted = []
    for step in range(6):
        if step in (0, 2):  # ticks 0 and 1
            send(link, step, step // 2, np.full(2, 10.0 + step), np.ones((2, 3)),
                 np.ones((2, 3)), np.ones((2, 3, 3)))
        deliver(link, step, thrust, rate, torque, rc)
        acted.append(thrust.copy())
    # THEN tick 0's thrust acts from step 2, tick 1's from step 4 (vehicle 1's was lost)
    assert [a[0] for a in acted] == [0.0, 0.0, 10.0, 10.0, 12.0, 12.0]
    assert [a[1] for a in acted] == [0.0, 0.0, 10.0, 10.0, 10.0, 10.0]


def test_losses_come_from_the_seed():
    a = lost_masks(1000, 4, 0.3, 5)
    b = lost_masks(1000, 4, 0.3, 5)
    c = lost_masks(1000, 4, 0.3, 6)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])
    assert a[0].mean() == pytest.approx(0.3, abs=0.03) and a[1].mean() == pytest.approx(0.3, abs=0.03)


def test_a_short_delay_still_converges_but_flies_differently():
    still = simulate(team_with(), SimOptions(log_rate_hz=20))
    late = simulate(team_with(link_delay_s=0.02), SimOptions(log_rate_hz=20))
    e_still = formation_error(still.log.position_enu_m, still.log.offsets_enu_m)
    e_late = formation_error(late.log.position_enu_m, late.log.offsets_enu_m)
    assert e_late[-1] < 1e-3
    assert not np.array_equal(e_still, e_late)


def test_without_delay_or_loss_the_link_is_off():
    assert not make_link(np.zeros(3, dtype=np.int64), np.zeros((5, 3), dtype=bool),
                         np.zeros((5, 3), dtype=bool), True).active


def test_a_lossy_delayed_batch_flies_each_team_as_alone():
    teams = [team_with(link_delay_s=d, link_loss=q, link_seed=s, predict=pr, duration_s=6.0)
             for d, q, s, pr in ((0.05, 0.2, 1, True), (0.0, 0.3, 2, True), (0.1, 0.0, 3, True))]
    options = SimOptions(log_rate_hz=50)
    together = simulate_batch(teams, options)
    for team, result in zip(teams, together, strict=True):
        alone = simulate(team, options)
        assert np.array_equal(result.log.position_enu_m, alone.log.position_enu_m)
        assert np.array_equal(result.log.mass_estimate_kg, alone.log.mass_estimate_kg)


def test_attitude_mode_converges_on_the_onboard_attitude_loop():
    gains = {"alpha_p": 1.5, "c_p": 0.6}
    result = simulate(team_with(mode="attitude", gains=gains, duration_s=40.0),
                      SimOptions(log_rate_hz=20))
    e = formation_error(result.log.position_enu_m, result.log.offsets_enu_m)
    assert e[0] > 1.0 and e[-1] < 1e-3
    # AND the law's inertia estimate is held: attitude mode sends no torque
    assert np.array_equal(result.log.inertia_estimate_kgm2[-1], result.log.inertia_estimate_kgm2[0])


def test_prediction_changes_what_a_delayed_law_reads():
    on = simulate(team_with(link_delay_s=0.03, predict=True, duration_s=10.0))
    off = simulate(team_with(link_delay_s=0.03, predict=False, duration_s=10.0))
    assert not np.array_equal(on.log.position_enu_m, off.log.position_enu_m)



def _rate_step(autopilot: str, axis: int, seconds: float = 1.5):
    """Body rate k of a vehicle whose rate command steps to 1 rad/s at t = 0, under the
    autopilot's response model (the rigid body integrated beside it, 1 kHz)."""
    from gcs.sim.autopilot import onboard_response
    from gcs.sim.loop import _response_loop

    onboard = onboard_response(autopilot, 1000.0, 1, np.array([9.81]))
    inertia = np.array([[0.05, 0.05, 0.09]])
    w, torque = np.zeros((1, 3)), np.zeros((1, 3))
    cmd = np.zeros((1, 3))
    cmd[0, axis] = 1.0
    out = []
    for step in range(int(seconds * 1000)):
        _response_loop(0, step, 1e-3, w, inertia, cmd, torque, onboard)
        w += 1e-3 * torque / inertia  # one axis moves: no gyroscopic coupling
        out.append(w[0, axis])
    return np.arange(1, len(out) + 1) * 1e-3, np.array(out)


def test_the_px4_response_model_answers_a_rate_step_as_recorded():
    # PX4's recorded fit (gcs/control/cascade.py): zeta 0.73, wn 19.1 rad/s, 4 ms dead time:
    # overshoot exp(-zeta pi / sqrt(1 - zeta^2)) = 3.5 %, peak at 4 ms + pi / (wn sqrt(1 - zeta^2))
    t, roll = _rate_step("px4", 0)
    assert roll.max() - 1.0 == pytest.approx(0.035, abs=0.01)
    assert t[roll.argmax()] == pytest.approx(0.004 + np.pi / (19.1 * np.sqrt(1 - 0.73**2)), abs=0.015)
    # AND yaw: first order 0.59 s after 99 ms: 63 % at 0.689 s
    t, yaw = _rate_step("px4", 2)
    assert t[np.argmax(yaw >= 1 - np.exp(-1))] == pytest.approx(0.689, abs=0.01)


def test_the_paper_gains_limit_cycle_on_px4s_loops_and_the_flown_ones_converge():
    # docs/gcs.md: the paper's k_eps 8 limit-cycles on PX4's rate loop; fly.rates' gains do not
    paper = simulate(team_with(autopilot="px4", telemetry_noise=False, duration_s=40.0),
                     SimOptions(log_rate_hz=20))
    soft = simulate(team_with(autopilot="px4", telemetry_noise=False, duration_s=40.0, gains={
        "alpha_p": 2.0, "c_p": 2.0, "k_eps": 1.5, "k_eps_yaw": 1.0}), SimOptions(log_rate_hz=20))
    e_paper = formation_error(paper.log.position_enu_m, paper.log.offsets_enu_m)
    e_soft = formation_error(soft.log.position_enu_m, soft.log.offsets_enu_m)
    assert e_paper[-200:].max() > 0.01 and e_soft[-200:].max() < 1e-3


def test_the_px4_telemetry_errors_have_their_fitted_sizes():
    from gcs.sim.noise import PX4_NOISE, add_telemetry_errors, make_noise, noise_draws

    ticks = 60000
    noise = make_noise(PX4_NOISE, ticks, 1, 0.01, noise_draws(4, ticks, 1))
    p, v, rot, w = np.zeros((1, 3)), np.zeros((1, 3)), np.eye(3)[None].copy(), np.zeros((1, 3))
    gyro, tilt, att = [], [], []
    for k in range(ticks):
        _, _, _, wo, _ = add_telemetry_errors(noise, k, p, v, rot, w, np.zeros((1, 3)), 9.81, 0.01)
        if k >= 3000:
            gyro.append(wo[0].copy())
            tilt.append(noise.state[0, :3].copy())
            att.append(noise.state[0, 3:6].copy())
    # THEN the stationary sizes are the personality's: gyro 0.14 / 0.07 / 0.03 per 4 ms sample
    # through 40 Hz, tilt integrated over 6 s, pitch 0.016 and heading 0.058 rad (second order)
    assert np.std(gyro, axis=0) == pytest.approx(
        [0.14 * np.sqrt(2 * 1.11 * 40 * 0.004), 0.07 * np.sqrt(2 * 1.11 * 40 * 0.004),
         0.03 * np.sqrt(2 * 1.11 * 40 * 0.004)], rel=0.05)
    assert np.std(tilt, axis=0)[:2] == pytest.approx(
        [0.14 * np.sqrt(0.004 * 3.0), 0.07 * np.sqrt(0.004 * 3.0)], rel=0.25)
    assert np.std(att, axis=0)[1:] == pytest.approx([0.016, 0.058], rel=0.25)


def _px4_mean_error_from_20_s(fly_key: str, values: tuple[float, ...]) -> list[float]:
    """Scenario I (40 s) on sim.autopilot px4 with the shipped rates gains, once per value of
    fly.<fly_key>: the mean formation error from t = 20 s of each."""
    gains = {"alpha_p": 2.0, "c_p": 2.0, "k_eps": 1.5, "k_eps_yaw": 1.0}
    errors = []
    for value in values:
        data = team_to_dict(team_with(autopilot="px4", gains=gains, link_seed=5, duration_s=40.0))
        data["fly"][fly_key] = value
        result = simulate(team_from_dict(data), SimOptions(log_rate_hz=20))
        e = formation_error(result.log.position_enu_m, result.log.offsets_enu_m)
        errors.append(e[result.log.t_s >= 20].mean())
    return errors


def test_gcs_flys_velocity_consistency_is_what_keeps_px4s_velocity_error_out_of_the_law():
    # docs/gcs.md: on the px4 personality, the reported velocity (T = 0) flies about twice the
    # error of v + low-passed (p' - v) (T = 0.2 s); the sim's px4 errors show the same
    errors = _px4_mean_error_from_20_s("velocity_from_position_s", (0.0, 0.2))
    assert errors[0] > 2.0 * errors[1] > 0.02


def test_the_acceleration_from_the_velocity_keeps_px4s_attitude_error_out_of_the_law():
    # docs/gcs.md "The law's acceleration": the accelerometer turned by PX4's reported attitude
    # reads its tilt and heading errors as accelerations; corrected toward the law velocity's
    # rate below 1 / 0.5 s the formation error drops by about a third
    errors = _px4_mean_error_from_20_s("acceleration_from_velocity_s", (0.0, 0.5))
    assert errors[0] > 1.2 * errors[1], errors


def test_a_noisy_batch_flies_each_team_as_alone():
    gains = {"alpha_p": 2.0, "c_p": 2.0, "k_eps": 1.5, "k_eps_yaw": 1.0}
    teams = [team_with(autopilot="px4", gains=gains, link_seed=s, duration_s=5.0) for s in (1, 2)]
    together = simulate_batch(teams, SimOptions(log_rate_hz=50))
    for team, result in zip(teams, together, strict=True):
        alone = simulate(team, SimOptions(log_rate_hz=50))
        assert np.array_equal(result.log.position_enu_m, alone.log.position_enu_m)
    assert not np.array_equal(together[0].log.position_enu_m, together[1].log.position_enu_m)
