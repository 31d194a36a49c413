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
    """Vehicle states whose every number is x (p, v, R, w), hovering (thrust m g)."""
    return (np.full((n, 3), x), np.full((n, 3), x), np.full((n, 3, 3), x), np.full((n, 3), x),
            np.full(n, 9.81), np.ones(n), 9.81)


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

