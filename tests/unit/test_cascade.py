"""The cascade criterion (gcs/control/cascade.py): its stability verdicts against a direct
time-domain simulation of the delayed loops, its margins against closed forms, and the gains it
proposes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gcs.control.cascade import (
    ARDUPILOT_RESPONSE,
    PX4_RESPONSE,
    AutopilotResponse,
    CascadeGains,
    cascade_margins,
    laplacian_eigenvalues,
    passes,
    stable_gains,
    verdict,
)
from gcs.fly.delay import unmeasured_delay_lines

PAPER = CascadeGains(alpha_p=2.0, c_p=4.0, k_eps=8.0, k_eps_yaw=8.0)
RING4 = np.array([[2, -1, 0, -1], [-1, 2, -1, 0], [0, -1, 2, -1], [-1, 0, -1, 2]], float)  # D - A
ROOT = Path(__file__).resolve().parents[2]
IDEAL = AutopilotResponse(1.0, 1e4, 0.0, 1e-4, 0.0, 1e4, 1e-5, "ideal")


def _attitude_loop_diverges(k: float, r: AutopilotResponse, loop_delay_s: float,
                            tau_s: float = 0.0, t_end_s: float = 6.0) -> bool:
    """Simulate theta' = w, w from the rate loop wn^2 / (s^2 + 2 zeta wn s + wn^2) driven by
    2 k (0 - theta) delayed by the loop delay plus the rate loop's dead time (Euler, 0.1 ms);
    with tau_s, the delayed attitude is carried forward by tau_s with the delayed rate,
    theta + tau w (the predictor, gcs/control/predict.py)."""
    dt = 1e-4
    lag = int(round((loop_delay_s + r.rate_dead_time_s) / dt))
    wn, z = r.rate_natural_radps, r.rate_damping
    theta, w, dw = 0.01, 0.0, 0.0
    history = [(theta, w)] * (lag + 1)
    peak_late = 0.0
    for step in range(int(t_end_s / dt)):
        th_d, w_d = history[-lag - 1]
        cmd = -2.0 * k * (th_d + tau_s * w_d)
        ddw = wn * wn * (cmd - w) - 2.0 * z * wn * dw
        dw += ddw * dt
        w += dw * dt
        theta += w * dt
        history.append((theta, w))
        if len(history) > lag + 2:
            history.pop(0)
        if step * dt > t_end_s - 1.0:
            peak_late = max(peak_late, abs(theta))
    return peak_late > 0.01


@pytest.mark.parametrize("k", [1.5, 3.0, 4.0, 8.0])
def test_attitude_loop_verdict_matches_a_time_domain_simulation(k):
    delay = 2 * (0.01 + 0.005)  # 10 ms each way plus half a 100 Hz tick each way
    margins = cascade_margins("rates", CascadeGains(1.0, 2.0, k, 0.5), PX4_RESPONSE, [0.0],
                              100.0, 0.01)
    roll = next(m for m in margins if m.loop.endswith("roll/pitch"))
    assert roll.stable == (not _attitude_loop_diverges(k, PX4_RESPONSE, delay))


def test_paper_loop_on_an_ideal_autopilot_has_its_closed_form_margin():
    # ideal inner loops: L = alpha_p (c_p lambda + 2 s) / s^2; |1 + L| = |s^2 + 4 s + 32| / |s|^2
    margins = cascade_margins("rates", PAPER, IDEAL, [4.0], 1e4, 0.0)
    horizontal = next(m for m in margins if "lambda=4" in m.loop and "horizontal" in m.loop)
    w = np.linspace(0.1, 100.0, 200001)
    closed_form = float(np.min(np.abs(-w * w + 4j * w + 32.0) / (w * w)))
    assert horizontal.stable
    assert horizontal.modulus_margin == pytest.approx(closed_form, abs=5e-3)


def test_ring_laplacian_eigenvalues():
    assert laplacian_eigenvalues(RING4) == pytest.approx([0.0, 2.0, 4.0])
    assert laplacian_eigenvalues(RING4)[0] == 0.0  # exactly: the common mode


def test_paper_gains_fail_on_px4_default_tuning_and_the_proposal_passes():
    ok, line = verdict("rates", PAPER, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.01, "PX4")
    assert not ok
    assert "is not stable enough" in line and "stable: rates mode with" in line
    proposal = stable_gains("rates", PAPER, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.01)
    assert proposal is not None
    assert passes(cascade_margins("rates", proposal, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.01))
    assert proposal.k_eps <= PAPER.k_eps and proposal.alpha_p <= PAPER.alpha_p
    assert proposal.c_p <= PAPER.c_p and proposal.k_eps_yaw <= PAPER.k_eps_yaw
    assert f"k_eps {proposal.k_eps:g}, k_eps_yaw {proposal.k_eps_yaw:g}" in line


def test_yaw_loop_of_the_paper_gain_is_unstable_on_both_autopilots():
    # PX4's yaw rate reaches 0.82 of a 1 rad/s step in 0.6 s: k_eps 8 about yaw cannot be flown
    for response in (PX4_RESPONSE, ARDUPILOT_RESPONSE):
        yaw = next(m for m in cascade_margins("rates", PAPER, response, [0.0], 100.0, 0.01)
                   if m.loop.endswith("yaw"))
        assert not yaw.ok()


def test_more_link_delay_never_helps():
    g = CascadeGains(1.0, 2.0, 1.5, 1.0)
    previous = math.inf
    for delay in (0.0, 0.01, 0.02, 0.05):
        smallest = min(m.modulus_margin for m in cascade_margins(
            "rates", g, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, delay))
        assert smallest <= previous + 1e-9
        previous = smallest
    ok, _ = verdict("rates", g, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.1, "PX4")
    assert not ok  # 100 ms each way is too much for these gains


def test_bundled_gains_pass_on_both_autopilots():
    from gcs.config import load_team
    from gcs.fly.setup import FlyOptions, prepare

    for name in ("square4.yaml", "square4_massdrop.yaml", "grid16.yaml"):
        team = load_team(ROOT / "configs" / name)
        for mode in ("rates", "attitude"):
            setup = prepare(team, FlyOptions(out_dir=Path("/nonexistent"), mode=mode))
            assert setup.plan.rules.loop_refusals == {}, (name, mode, setup.stability)
            assert setup.stability.count("every loop passes") == 2, setup.stability


def test_a_measured_delay_above_the_configured_one_is_judged_again_per_autopilot():
    from gcs.fly.delay import DelayJudge

    g = CascadeGains(1.0, 2.0, 1.5, 1.0)  # the bundled rates gains: pass at 10 ms on PX4
    judge = DelayJudge("rates", g, [0.0, 2.0, 4.0], 100.0, 0.01)
    px4, ardupilot = 12, 3
    # within the configured delay, or nothing measured: nothing to say
    assert judge.problem(px4, np.array([0.004, 0.02, 0.019])) is None
    # 12 ms each way: within the 5 ms tolerance of the configured 10 ms, flown as configured
    assert judge.problem(px4, np.array([0.024, 0.024])) is None
    # a busy machine delays a few replies: the lower quartile passes over them
    assert judge.problem(px4, np.array([0.001] * 15 + [0.040] * 5)) is None
    assert judge.problem(px4, np.array([])) is None
    # a 110 ms round trip: 55 ms each way, where these gains fail (test_more_link_delay...)
    assert not verdict("rates", g, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.055, "PX4")[0]
    line = judge.problem(px4, np.array([0.110, 0.110, 0.110, 0.150]))
    assert line is not None
    assert line.startswith("link delay measured 55 ms each way (TIMESYNC round trip lower "
                           "quartile 110 ms), more than fly.link_delay_s 10 ms: rates mode with")
    assert "link delay 55 ms, on PX4" in line and "stable: rates mode with" in line
    assert "on ArduPilot Copter" in judge.problem(ardupilot, np.array([0.11]))
    # a flight configured for no delay at all measures 10 ms each way: stable there, flown
    assert verdict("rates", g, PX4_RESPONSE, [0.0, 2.0, 4.0], 100.0, 0.010, "PX4")[0]
    assert DelayJudge("rates", g, [0.0, 2.0, 4.0], 100.0, 0.0).problem(
        px4, np.array([0.0199, 0.0200, 0.0201])) is None


def test_the_delay_judge_is_asked_only_when_a_preflight_decides_and_from_the_settled_links(
        monkeypatch):
    # the statuses are built on every tick: a verdict there cost a criterion evaluation per new
    # 5 ms step, and a large team's round trips, lifted by its own configure step, spread over
    # hundreds of steps; the stall lifted them further and COMMAND_ACKs were lost. Those round
    # trips do not count either: only the ones since the configure step ended
    import gcs.fly.delay as delay
    from gcs.link.clock import VehicleClock
    from gcs.mission.safety import SafetyRules, VehicleStatus, preflight_problems

    evaluated, built = [], []

    def counting_margins(*args, **kwargs):
        evaluated.append(args[5])
        return cascade_margins(*args, **kwargs)

    def counting_verdict(*args, **kwargs):
        built.append(args[5])
        return verdict(*args, **kwargs)

    monkeypatch.setattr(delay, "cascade_margins", counting_margins)
    monkeypatch.setattr(delay, "verdict", counting_verdict)
    # softer gains than the bundled ones: on PX4 they pass up to 55 ms each way, fail at 60
    judge = delay.DelayJudge("rates", CascadeGains(1.0, 1.0, 1.0, 0.5), [0.0, 2.0, 4.0], 100.0,
                             0.01)
    configured_s = 10.0
    clocks = [VehicleClock() for _ in range(96)]
    for i, c in enumerate(clocks):  # while the team was configured: 30-980 ms
        for k in range(4):
            c.on_round_trip(0.03 + 0.01 * i, sent_s=8.0 + 0.5 * k)
    deferred = [judge.deferred(12, c) for c in clocks]
    assert evaluated == [] and built == []
    for i, c in enumerate(clocks):  # settled: 24-38 ms
        for k in range(4):
            c.on_round_trip(0.024 + 0.002 * (i % 8), sent_s=configured_s + 0.5 * k)
    statuses = [VehicleStatus(vehicle_id=i + 1, sysid=i + 1, link="alive", armed=False,
                              mode="", landed=True, position_enu_m=(0.0, 0.0, 0.0),
                              velocity_enu_mps=(0.0, 0.0, 0.0), tilt_rad=0.0, data_age_s=0.0,
                              autopilot=12, vehicle_type=2, loop_problem=d)
                for i, d in enumerate(deferred)]
    assert preflight_problems(statuses, SafetyRules(), configured_s) == []
    # 12-19 ms each way: 15 ms (flown as configured, within the tolerance) and 20 ms, judged once
    assert evaluated == [0.02] and built == []
    # links whose delay stays at 55-61 ms: refused, the line built once per step
    for c, rtts in zip(clocks[:2], ([0.110, 0.112, 0.114, 0.122] * 2, [0.122] * 8), strict=True):
        for k, rtt in enumerate(rtts):
            c.on_round_trip(rtt, sent_s=configured_s + 1.0 + 0.5 * k)
    lines = [d(configured_s) for d in deferred[:2]]
    assert built == [0.06, 0.065] and all(line is not None for line in lines)
    assert lines[0].startswith("link delay measured 56 ms") and "link delay 60 ms" in lines[0]
    assert deferred[0](configured_s) == lines[0] and built == [0.06, 0.065]
    # fewer than 4 since then: the latest 8, whenever they were sent (two are too few)
    late = VehicleClock()
    for k, rtt in enumerate([0.024] * 6 + [0.110] * 2):
        late.on_round_trip(rtt, sent_s=configured_s - 3.0 + 0.5 * k)
    assert judge.deferred(12, late)(configured_s) is None


@pytest.mark.parametrize("k", [1.5, 2.0, 3.0, 4.0])
def test_the_predicted_attitude_loop_verdict_matches_a_time_domain_simulation(k):
    # 100 ms each way on the nominal autopilot, the law reading the attitude predicted over the
    # sample's age plus the uplink: tau = 2 x 100 ms + half a tick
    from gcs.control.cascade import NOMINAL_RESPONSE, prediction_horizon_s

    link = 0.1
    margins = cascade_margins("rates", CascadeGains(1.0, 1.0, k, 0.5), NOMINAL_RESPONSE, [0.0],
                              100.0, link, predicted=True)
    roll = next(m for m in margins if m.loop.endswith("roll/pitch"))
    tau = prediction_horizon_s(100.0, link, True)
    assert tau == pytest.approx(0.205)
    assert roll.stable == (not _attitude_loop_diverges(
        k, NOMINAL_RESPONSE, 2 * (link + 0.005), tau))


def _vertical_loop_grows(alpha_p: float, c_p: float, lam: float, d_down: float, d_up: float,
                         tau: float, t_end_s: float = 60.0) -> bool:
    """x'' = u(t - d_up), u = -alpha_p (c_p lam xh + 2 vh) from the states d_down old, predicted
    over tau (xh = x + v tau + a tau^2 / 2, vh = v + a tau, a the measured x''): True when the
    last 5 s swing wider than the first (Euler, 1 ms)."""
    dt = 1e-3
    n_down, n_up = int(round(d_down / dt)), int(round(d_up / dt))
    x, v = 1.0, 0.0
    states = [(x, v, 0.0)] * (n_down + 1)
    commands = [0.0] * (n_up + 1)
    early = late = 0.0
    for step in range(int(t_end_s / dt)):
        xd, vd, ad = states[-n_down - 1]
        commands.append(-alpha_p * (c_p * lam * (xd + vd * tau + 0.5 * ad * tau * tau)
                                    + 2.0 * (vd + ad * tau)))
        a = commands[-n_up - 2]
        v += a * dt
        x += v * dt
        states.append((x, v, a))
        del states[0], commands[0]
        t = step * dt
        if t < 5.0:
            early = max(early, abs(x))
        elif t > t_end_s - 5.0:
            late = max(late, abs(x))
    return late > early


@pytest.mark.parametrize(("link", "predicted", "alpha_p", "c_p"), [
    (0.1, False, 2.0, 2.0), (0.1, False, 2.0, 4.0),
    (0.1, True, 0.5, 1.0), (0.1, True, 1.0, 2.0), (0.1, True, 2.0, 4.0), (0.1, True, 4.0, 4.0),
    (0.2, False, 0.5, 1.0), (0.2, True, 0.5, 1.0), (0.2, True, 1.0, 2.0),
    # where the verdicts differ: prediction stabilises a soft loop, destabilises a stiffer one
    (0.2, False, 0.25, 4.0), (0.2, True, 0.25, 4.0), (0.3, False, 0.25, 2.0),
    (0.3, True, 0.25, 2.0),
])
def test_the_position_loop_verdict_with_and_without_prediction_matches_a_simulation(
        link, predicted, alpha_p, c_p):
    # the vertical loop on an ideal autopilot (thrust applied at once) over `link` each way
    from gcs.control.cascade import prediction_horizon_s

    tick = 1e4
    margins = cascade_margins("rates", CascadeGains(alpha_p, c_p, 1.0, 0.5), IDEAL, [2.0], tick,
                              link, predicted=predicted)
    vertical = next(m for m in margins if "vertical" in m.loop)
    d = link + 0.5 / tick
    tau = prediction_horizon_s(tick, link, predicted)
    assert vertical.stable == (not _vertical_loop_grows(alpha_p, c_p, 2.0, d, d, tau))


def test_prediction_buys_stiffness_at_a_lasting_delay_and_makes_attitude_mode_the_tolerant_one():
    from gcs.control.cascade import NOMINAL_RESPONSE

    def stiffness(mode, response, delay, predicted):
        g = stable_gains(mode, PAPER, response, [0.0, 2.0, 4.0], 100.0, delay, predicted)
        return 0.0 if g is None else g.alpha_p * g.c_p

    for response in (NOMINAL_RESPONSE, PX4_RESPONSE, ARDUPILOT_RESPONSE):
        # attitude mode: the autopilot closes the attitude loop on board, the link is in the
        # position loop only, which the predictor compensates: stiffer at every delay from 20 ms,
        # and the only mode with stable gains at 200 ms each way
        for delay in (0.02, 0.05, 0.1):
            assert stiffness("attitude", response, delay, True) > stiffness(
                "attitude", response, delay, False), (response.source, delay)
        assert stiffness("attitude", response, 0.2, True) > 0.0
        assert stiffness("rates", response, 0.2, True) == 0.0
        assert stiffness("rates", response, 0.2, False) == 0.0


def test_a_link_whose_timesync_requests_got_no_reply_is_named_with_the_delay_assumed():
    # GIVEN two links at the law's start: one timed 8 round trips, one got no reply to 40
    # requests (real PX4's replies before the codec read past their newer fields)
    links = [("vehicle 1 (sysid 1)", 8, 40), ("vehicle 2 (sysid 2)", 0, 40)]
    # THEN only the second is named, with the configured delay the rules take instead
    assert unmeasured_delay_lines(links, 0.5, 0.01) == [
        "vehicle 2 (sysid 2): no reply to its 40 TIMESYNC requests: its link delay is not "
        "measured; the delay rules take fly.link_delay_s (10 ms) for it"]
    # AND with the requests switched off, one line says no link was measured
    (line,) = unmeasured_delay_lines(links, 0.0, 0.02)
    assert line.startswith("link delays not measured") and "(20 ms)" in line


def test_actuators_mode_is_judged_again_at_each_links_round_trip_per_vehicle_inertia():
    from gcs.fly.delay import TorqueDelayJudge

    # GIVEN Scenario I's inertias and the flown torque gains at 250 Hz
    inertia = [(0.04856, 0.04856, 0.08801), (0.1522, 0.1522, 0.3), (0.0256, 0.0256, 0.052),
               (0.354, 0.354, 0.654)]
    judge = TorqueDelayJudge([1, 2, 3, 4], inertia, 2.0, 2.0, 250.0)
    # localhost (round trips 0.4-0.8 ms, busy or not): the ground station's own 16 ms span
    # covers it, and nothing measured says nothing
    for i in range(4):
        assert judge.problem(i, np.array([0.0004, 0.0006, 0.0008])) is None
        assert judge.problem(i, np.array([])) is None
    # a 10 ms round trip: UAV 3 (J 0.0256) fails from 5 ticks of delay, UAV 4 (J >= 0.354) not
    line = judge.problem(2, np.array([0.010] * 8))
    assert line is not None and line.startswith(
        "link delay measured 5 ms each way (TIMESYNC round trip lower quartile 10 ms): "
        "actuators mode at 250 Hz with alpha_eps 2, alpha_omega 2 is not stable when the torque "
        "acts up to 7 ticks late: axis x (J 0.0256 kg m^2)")
    assert line.endswith("fly rates mode, whose attitude loop the autopilot closes on board")
    assert judge.problem(3, np.array([0.010] * 8)) is None
    # 50 ms each way (the link test's): UAVs 1-3 are refused; UAV 4's slow loop (J 0.354-0.654)
    # still decays at 1.5 /s with its torque 29 ticks late
    assert [judge.problem(i, np.array([0.100] * 8)) is None for i in range(4)] == [
        False, False, False, True]
