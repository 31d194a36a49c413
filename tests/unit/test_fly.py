"""`gcs fly` without sockets: setup and its stability check, the staleness rule, setpoint scaling,
tick statistics, and the distributed structure of the team computation."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from flightkit.physics import rotors_from_wrench, wrench_from_rotors
from gcs.config import load_team
from gcs.config.fly_schema import ResponseConfig
from gcs.control.cascade import CascadeGains, laplacian_eigenvalues, verdict
from gcs.control.formation import edge_list, reference_velocity
from gcs.control.geometry import rotation_from_rpy
from gcs.control.law import TeamLaw, TeamMeasurement
from gcs.fly.flight import Flight
from gcs.fly.measure import (
    command_heading_rad,
    desaturate_torque,
    drop_stale_neighbours,
    level_rotations,
    limit_rate_command,
    normalised_thrust,
    torque_max_nm,
    yaw_rad,
)
from gcs.fly.setup import FlightSetupError, FlyOptions, prepare, true_mass_kg
from gcs.fly.stats import (
    AgeStats,
    TickStats,
    late_threshold_s,
    link_report,
    log_due,
    round_trip_report,
)
from gcs.mission.autopilots import PROFILES
from gcs.sim.runner import law_gains

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
OUT = Path("/nonexistent")


def test_rates_setup_uses_the_file_and_checks_the_criterion():
    team = load_team(CONFIGS / "square4.yaml")
    setup = prepare(team, FlyOptions(out_dir=OUT, mode="rates"))
    assert setup.tick_rate_hz == 100.0 and setup.log_every == 2
    # every stream the law and preflight need, EXTENDED_SYS_STATE (landed state) included
    # (and ATTITUDE_TARGET: fly.initial_mass from_hover reads the hover thrust)
    assert setup.requested_rates_hz == {"ATTITUDE_QUATERNION": 100.0, "LOCAL_POSITION_NED": 100.0,
                                        "EXTENDED_SYS_STATE": 5.0, "HIGHRES_IMU": 100.0,
                                        "ATTITUDE_TARGET": 10.0}
    # fly.rates flies the cascade criterion's gains, not the paper's (gcs/control/cascade.py)
    assert (setup.gains.k_eps, setup.gains.k_eps_yaw, setup.gains.alpha_p, setup.gains.c_p) == (
        1.5, 1.0, 2.0, 2.0)
    # judged with the delay compensation the law flies with (fly.predict, on by default)
    assert ("rates mode with k_eps 1.5, k_eps_yaw 1, alpha_p 2, c_p 2 at 100 Hz, link delay "
            "10 ms (compensated, fly.predict), on PX4") in setup.stability
    assert setup.plan.rules.loop_refusals == {}


def _paper_rates(team):
    fly = dataclasses.replace(team.fly, rates=dataclasses.replace(
        team.fly.rates, k_eps=None, k_eps_yaw=None, alpha_p=None, c_p=None))
    return dataclasses.replace(team, fly=fly)


def test_paper_gains_in_rates_mode_are_refused_for_px4_and_ardupilot_vehicles():
    setup = prepare(_paper_rates(load_team(CONFIGS / "square4.yaml")),
                    FlyOptions(out_dir=OUT, mode="rates"))
    assert setup.gains.k_eps == 8.0 and setup.gains.alpha_p == 2.0
    refusals = setup.plan.rules.loop_refusals
    assert set(refusals) == {12, 3}
    assert refusals[12].startswith(
        "rates mode with k_eps 8, k_eps_yaw 8, alpha_p 2, c_p 4 at 100 Hz, link delay 10 ms "
        "(compensated, fly.predict), on PX4 (PX4 v1.16.0 SIH default tuning (recorded rate doublets)) is not stable enough: ")
    assert "; stable: rates mode with k_eps 2, k_eps_yaw 1, alpha_p 2, c_p 2 (fly.rates)" in (
        refusals[12])


def test_a_declared_response_that_fails_is_refused_before_any_link_opens():
    team = _paper_rates(load_team(CONFIGS / "square4.yaml"))
    response = ResponseConfig(rate_damping=0.3, rate_natural_radps=14.7, rate_dead_time_s=0.004,
                              yaw_time_constant_s=0.59, yaw_dead_time_s=0.099,
                              attitude_p_per_s=6.5, thrust_time_constant_s=0.05)
    team = dataclasses.replace(team, fly=dataclasses.replace(team.fly, response=response))
    with pytest.raises(FlightSetupError, match=r"^rates mode with k_eps 8, .* on every vehicle \(the "
                       r"team file's fly.response\) is not stable enough: "):
        prepare(team, FlyOptions(out_dir=OUT, mode="rates"))


def test_initial_mass_from_hover_applies_to_every_vehicle_in_flight_only():
    team = load_team(CONFIGS / "square4.yaml")
    assert team.fly.initial_mass == "from_hover"
    assert not any(v.estimates.from_hover for v in team.vehicles)  # gcs sim: the scenario's
    setup = prepare(team, FlyOptions(out_dir=OUT, mode="rates"))
    assert all(v.estimates.from_hover for v in setup.team.vehicles)
    assert setup.requested_rates_hz["ATTITUDE_TARGET"] == 10.0


def test_actuators_setup_flies_the_criterion_gains_at_250_hz():
    team = load_team(CONFIGS / "square4.yaml")
    setup = prepare(team, FlyOptions(out_dir=OUT, mode="actuators"))
    assert setup.mode == "actuators" and setup.tick_rate_hz == 250.0
    assert (setup.gains.alpha_eps, setup.gains.alpha_omega) == (2.0, 2.0)
    # (27) adapts at the paper's alpha_rho scaled as alpha_omega was (0.5 * 2/32 ~ 0.03)
    assert setup.gains.alpha_rho == 0.03 and team.controller.gains.alpha_rho == 0.5
    assert prepare(team, FlyOptions(out_dir=OUT, mode="rates")).gains.alpha_rho == 0.5
    assert setup.requested_rates_hz["ATTITUDE_QUATERNION"] == 250.0
    assert setup.requested_rates_hz["LOCAL_POSITION_NED"] == 100.0


def test_paper_torque_gains_at_250_hz_are_refused_before_any_link_opens():
    team = load_team(CONFIGS / "square4.yaml")
    fly = dataclasses.replace(team.fly, actuators=dataclasses.replace(
        team.fly.actuators, alpha_eps=None, alpha_omega=None))
    team = dataclasses.replace(team, fly=fly)
    with pytest.raises(FlightSetupError, match=r"^actuators mode at 250 Hz is not stable with "
                       r"alpha_eps 32, alpha_omega 32: vehicle 3 axis [xy] \(J 0.0256 kg m\^2\)"):
        prepare(team, FlyOptions(out_dir=OUT, mode="actuators"))


def _with_fly(team, **changes):
    return dataclasses.replace(team, fly=dataclasses.replace(team.fly, **changes))


def _passes_everywhere(team, mode: str) -> bool:
    """The cascade criterion of `mode` with the file's gains for it, on every autopilot profile
    (evaluated here through `verdict`, the preflight's own per-autopilot judgement)."""
    m = team.fly.mode(mode)
    g = team.controller.gains
    gains = CascadeGains(m.alpha_p or g.alpha_p, m.c_p or g.c_p, m.k_eps or g.k_eps,
                         m.k_eps_yaw or g.k_eps_yaw)
    eig = laplacian_eigenvalues(team.laplacian())
    return all(verdict(mode, gains, p.response, eig, m.tick_rate_hz, team.fly.link_delay_s,
                       p.name, team.fly.predict)[0] for p in PROFILES.values())


def test_fly_mode_auto_is_the_default_and_flies_rates_where_its_loops_pass():
    team = load_team(CONFIGS / "square4.yaml")
    assert team.controller.mode == "actuators"  # gcs sim's: the paper's torque law
    assert team.fly.control_mode == "auto"
    assert _passes_everywhere(team, "rates")
    setup = prepare(team, FlyOptions(out_dir=OUT))
    assert setup.mode == "rates" and setup.tick_rate_hz == 100.0
    assert setup.gains.k_eps == team.fly.rates.k_eps
    assert setup.mode_choice.startswith("mode rates (auto: ")
    assert "PX4 and ArduPilot Copter with fly.rates's gains at link delay 10 ms" in (
        setup.mode_choice)
    # --mode and fly.mode choose outright, actuators included
    assert prepare(team, FlyOptions(out_dir=OUT, mode="actuators")).mode == "actuators"
    chosen = prepare(_with_fly(team, control_mode="attitude"), FlyOptions(out_dir=OUT))
    assert (chosen.mode, chosen.mode_choice) == ("attitude", "mode attitude (fly.mode)")
    with pytest.raises(FlightSetupError, match=r"mode 'torque': expected one of \('auto', "):
        prepare(team, FlyOptions(out_dir=OUT, mode="torque"))


def test_fly_mode_auto_takes_attitude_where_the_declared_delay_fails_rates_on_one_autopilot():
    team = _with_fly(load_team(CONFIGS / "grid16.yaml"), link_delay_s=0.06)
    assert not _passes_everywhere(team, "rates") and _passes_everywhere(team, "attitude")
    setup = prepare(team, FlyOptions(out_dir=OUT))
    assert setup.mode == "attitude" and setup.gains.c_p == team.fly.attitude.c_p
    assert setup.mode_choice.endswith("at link delay 60 ms; rates fails on PX4)")
    assert setup.plan.rules.loop_refusals == {}


def test_fly_mode_auto_flies_rates_and_lets_preflight_refuse_when_no_mode_passes():
    team = _with_fly(load_team(CONFIGS / "square4.yaml"), link_delay_s=0.2)
    assert not _passes_everywhere(team, "rates") and not _passes_everywhere(team, "attitude")
    setup = prepare(team, FlyOptions(out_dir=OUT))
    assert setup.mode == "rates"
    assert "no mode passes on every autopilot with the file's gains at link delay 200 ms: " in (
        setup.mode_choice)
    assert "attitude fails on PX4" in setup.mode_choice
    assert set(setup.plan.rules.loop_refusals) == {12, 3}  # both autopilots' vehicles refused


def test_tick_rate_must_be_a_multiple_of_the_log_rate():
    team = load_team(CONFIGS / "square4.yaml")
    with pytest.raises(FlightSetupError, match="tick rate 75 Hz must be a multiple of"):
        prepare(team, FlyOptions(out_dir=OUT, mode="rates", tick_rate_hz=75.0))


def test_true_mass_follows_the_scheduled_drop():
    team = load_team(CONFIGS / "square4_massdrop.yaml")
    np.testing.assert_allclose(true_mass_kg(team, 39.99), [0.85, 1.2, 0.35, 3.4])
    np.testing.assert_allclose(true_mass_kg(team, 40.0), [0.595, 1.2, 0.35, 3.4])


def test_stale_neighbour_edges_are_dropped_in_their_neighbours_rows_only():
    a = np.array([[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0]], dtype=float)
    fresh = np.array([True, False, True, True])
    graph = edge_list(a)
    weight = np.full_like(graph.weight, np.nan)
    # WHEN the staleness rule is applied to the edge list in place
    stale = drop_stale_neighbours(graph, fresh, weight)
    eff = np.zeros((4, 4))
    for i in range(4):
        for e in range(graph.row_start[i], graph.row_start[i + 1]):
            eff[i, graph.neighbour[e]] = weight[e]
    # THEN vehicles 1 and 3 stop using vehicle 2, which still uses its fresh neighbours
    assert eff[0, 1] == 0 and eff[2, 1] == 0
    np.testing.assert_array_equal(eff[1], a[1])
    np.testing.assert_array_equal(eff, a * fresh[None, :])
    np.testing.assert_array_equal(stale, [1, 0, 1, 0])
    # AND the configured weights are untouched (the next tick starts from them)
    np.testing.assert_array_equal(graph.weight, np.ones(8))


def test_thrust_is_normalised_by_max_thrust_never_by_mass():
    team = load_team(CONFIGS / "square4.yaml")
    max_n = np.array([v.airframe.max_thrust_n for v in team.vehicles])
    np.testing.assert_allclose(normalised_thrust([12.0, 16.0, 6.0, 40.0], max_n),
                               [0.5, 0.5, 0.5, 0.5])


def test_rate_limit_keeps_the_direction():
    out, clipped = limit_rate_command(np.array([[3.0, 4.0, 0.0], [0.1, 0.0, 0.0]]), 1.0)
    np.testing.assert_allclose(out, [[0.6, 0.8, 0.0], [0.1, 0.0, 0.0]])
    assert clipped.tolist() == [True, False]


def test_the_yaw_rate_is_limited_on_its_own_and_never_shrinks_roll_and_pitch():
    cmd = np.array([[0.3, -0.4, 2.0], [3.0, 4.0, -0.2], [0.1, 0.1, 0.1]])
    out, clipped = limit_rate_command(cmd, 1.0, 0.5)
    # THEN the first row keeps its roll/pitch and loses yaw; the second keeps its yaw
    np.testing.assert_allclose(out, [[0.3, -0.4, 0.5], [0.6, 0.8, -0.2], [0.1, 0.1, 0.1]])
    assert clipped.tolist() == [True, True, False]


def test_heading_policies_hold_keep_the_start_heading_or_fix_a_compass_heading():
    rot = np.stack([rotation_from_rpy(0.1, -0.05, yaw) for yaw in (0.3, -2.0, 3.0)])
    np.testing.assert_allclose(yaw_rad(rot), [0.3, -2.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(command_heading_rad("hold", rot), [0.3, -2.0, 3.0], atol=1e-12)
    np.testing.assert_array_equal(command_heading_rad("paper", rot), 0.0)
    # compass 0 (north) is ENU yaw +90 deg; 90 (east) is ENU yaw 0
    np.testing.assert_allclose(command_heading_rad(0.0, rot), np.pi / 2)
    np.testing.assert_allclose(command_heading_rad(90.0, rot), 0.0, atol=1e-15)
    with pytest.raises(ValueError, match="fly.heading 'north'"):
        command_heading_rad("north", rot)
    level = level_rotations(rot)
    np.testing.assert_allclose(level[:, :, 2], [[0, 0, 1]] * 3, atol=1e-15)
    np.testing.assert_allclose(yaw_rad(level), [0.3, -2.0, 3.0], atol=1e-12)


def test_desaturated_torque_is_realised_exactly_by_the_mixer_at_the_commanded_thrust():
    # GIVEN random wrenches, some far beyond what the rotors can do
    rng = np.random.default_rng(1)
    n = 200
    d, c, fmax = np.full(n, 0.12), np.full(n, 0.016), np.full(n, 3.0)
    thrust = rng.uniform(0.2, 11.8, n)
    torque = rng.normal(0.0, 0.3, (n, 3))
    # WHEN limited THEN the emulator's mixer (51) returns that wrench unchanged (thrust kept)
    limited, was = desaturate_torque(thrust, torque, d, c, fmax)
    rotors = rotors_from_wrench(thrust, limited, d, c, fmax)
    t_out, tau_out = wrench_from_rotors(rotors, d, c)
    np.testing.assert_allclose(t_out, thrust, atol=1e-9)
    np.testing.assert_allclose(tau_out, limited, atol=1e-9)
    # AND a feasible torque is untouched, an infeasible one only scaled down
    assert was.any() and not was.all()
    np.testing.assert_allclose(limited[~was], torque[~was])
    assert np.all(np.abs(limited) <= np.abs(torque) + 1e-12)


def test_torque_scale_is_the_emulators_convention():
    np.testing.assert_allclose(torque_max_nm([0.12], [0.016], [3.0]), [[0.36, 0.36, 0.096]])


def test_tick_stats_count_late_ticks_against_a_fifth_of_the_period():
    assert late_threshold_s(0.01) == pytest.approx(2e-3)
    assert late_threshold_s(0.004) == pytest.approx(1.5e-3)
    stats = TickStats(100.0)
    for late in [0.0005] * 98 + [0.003, 0.012]:
        stats.record(late, 0.001)
    r = stats.report()
    assert r["rate_hz"] == 100.0 and r["late_pct"] == pytest.approx(2.0) and r["ticks"] == 100


def test_a_skipped_tick_counts_as_late_among_all_deadlines():
    # GIVEN 98 ticks run on time, 1 late, and a stall that jumped over one deadline
    stats = TickStats(100.0)
    for late in [0.0005] * 98 + [0.003]:
        stats.record(late, 0.001)
    assert stats.skip(1, 3.0) is None  # 20 ms without a tick: late, not a stall
    # THEN 2 of the 100 deadlines were not met on time
    r = stats.report()
    assert r["late_pct"] == pytest.approx(2.0) and r["ticks"] == 99 and r["skipped_ticks"] == 1
    assert r["stalls"] == 0 and r["stalls_at_s_ms"] == []


def test_a_tick_gap_of_50_ms_or_more_is_a_stall_with_its_time_and_length():
    # GIVEN a 250 Hz loop that jumped over 24 deadlines at 1.64 s (100 ms without a tick) and
    # over 11 at 5 s (48 ms)
    stats = TickStats(250.0)
    assert stats.skip(24, 1.64) == pytest.approx(0.1)
    assert stats.skip(11, 5.0) is None
    # THEN the report counts one stall and lists it
    r = stats.report()
    assert r["skipped_ticks"] == 35 and r["stalls"] == 1
    assert r["stalls_at_s_ms"] == [[1.64, 100.0]]


def test_a_log_sample_whose_tick_was_skipped_is_taken_at_the_next_tick_run():
    # GIVEN a log sample every 10th tick from k0 = 7, and a loop that ran these ticks (a stall
    # jumped over 27, 28 and 37..45: the log samples of ticks 27 and 37 were never run)
    ran = [*range(7, 27), 29, *range(30, 37), 46, *range(47, 60)]
    taken, next_k = [], 7
    for k in ran:
        due, next_k = log_due(k, 7, 10, next_k)
        if due:
            taken.append(k)
    # THEN every sample is in the record, the skipped ones at the first tick after theirs, and
    # the grid picks up again on time (no sample twice, none moved later than it had to)
    assert taken == [7, 17, 29, 46, 47, 57]


def test_link_report_has_the_spec_fields():
    ages = AgeStats(2)
    # true ages 54 / 200 ms, received 4 / 200 ms ago (vehicle 7's link adds 50 ms)
    ages.record(np.array([0.054, 0.2]), np.array([0.004, 0.2]), np.array([True, False]),
                np.array([1, 0]))
    ages.record(np.array([0.060, 0.3]), np.array([0.010, 0.3]), np.array([True, False]),
                np.array([1, 0]))
    r = link_report([7, 9], ages, [10, 20], [100, 90], [0, 10])
    assert set(r) == {"7", "9"}
    assert r["9"]["telemetry_lost_pct"] == pytest.approx(10.0)
    assert r["7"]["telemetry_age_p50_ms"] == pytest.approx(57.0)
    assert r["7"]["telemetry_age_max_ms"] == pytest.approx(60.0)
    assert r["7"]["receive_age_p99_ms"] == pytest.approx(9.94)
    assert r["9"]["stale_own_ticks"] == 2 and r["7"]["stale_neighbour_ticks"] == 2


def test_round_trips_are_reported_in_milliseconds_and_an_unanswered_link_says_so():
    r = round_trip_report(np.array([0.1, 0.102, 0.104, 0.3]))
    assert r["n"] == 4 and r["max_ms"] == pytest.approx(300.0)
    assert r["p50_ms"] == pytest.approx(103.0)
    assert round_trip_report(np.array([])) == {"n": 0, "p50_ms": None, "p99_ms": None,
                                               "max_ms": None}


def test_each_row_of_the_team_call_is_what_that_vehicle_would_compute_alone():
    # GIVEN the team law in one vectorised call
    team = load_team(CONFIGS / "square4.yaml")
    rng = np.random.default_rng(3)
    n = team.n
    adj = team.adjacency()
    meas = TeamMeasurement(
        team.initial_positions_enu_m() + rng.normal(0, 0.3, (n, 3)), rng.normal(0, 0.3, (n, 3)),
        rng.normal(0, 0.5, (n, 3)), np.tile(np.eye(3), (n, 1, 1)), rng.normal(0, 0.1, (n, 3)))
    ref = reference_velocity(1.3, *team.reference_velocity.as_arrays())

    def law(adjacency, offsets, mhat):
        return TeamLaw(law_gains(team), adjacency, offsets, mhat,
                       np.full((len(mhat), 3), 0.08))

    batch = law(adj, team.offsets_enu_m(), team.initial_mhat()).step(meas, ref, 0.01)
    for i in range(n):
        # WHEN vehicle i computes on its own: itself + its neighbours' telemetry, its own mhat
        hood = [i] + [j for j in range(n) if adj[i, j] != 0]
        local_adj = np.zeros((len(hood), len(hood)))
        local_adj[0] = adj[i, hood]
        mhat = team.initial_mhat()[hood] * 0 + 99.0  # neighbours' estimates must not matter
        mhat[0] = team.initial_mhat()[i]
        sub = TeamMeasurement(*(np.ascontiguousarray(getattr(meas, f)[hood]) for f in
                                ("position_m", "velocity_mps", "acceleration_mps2", "rotation",
                                 "omega_radps")))
        alone = law(local_adj, team.offsets_enu_m()[hood], mhat).step(sub, ref, 0.01)
        # THEN it gets exactly its row of the team call
        np.testing.assert_allclose(alone.rate_cmd_radps[0], batch.rate_cmd_radps[i], rtol=1e-12)
        np.testing.assert_allclose(alone.torque_nm[0], batch.torque_nm[i], rtol=1e-12)
        assert alone.thrust_n[0] == pytest.approx(batch.thrust_n[i], rel=1e-12)


def test_hover_thrust_gives_the_thrust_equivalent_mass_and_checks_proposition_2():
    from gcs.fly.measure import HOVER_MIN_SAMPLES, HoverThrust

    h = HoverThrust(2)
    for k in range(40):  # 4 s at 10 Hz, thrust 0.49 +- 0.01
        assert h.add(0, 10.0 + 0.1 * k, 0.49 + 0.01 * (-1) ** k)
    assert not h.add(0, 10.0, 0.5)  # not newer: ignored
    assert not h.add(0, 20.0, float("nan")) and not h.add(0, 20.0, 1.5)
    # THEN the last 2 s give 0.49 * 20 N / g, and mhat(0) = phi(0) m / alpha_m
    est = h.estimate(0, 13.95, max_thrust_n=20.0, alpha_m=1.0, phi0=2.0, mass_bound_kg=1.5)
    assert est is not None and est.samples == 20
    assert est.mass_kg == pytest.approx(0.49 * 20.0 / 9.81, rel=1e-3)
    assert est.mhat0 == pytest.approx(2.0 * est.mass_kg) and est.proposition2_holds
    # a mass bound above twice the hover mass fails Proposition 2 (phi(0) = 2)
    low = h.estimate(0, 13.95, max_thrust_n=20.0, alpha_m=1.0, phi0=2.0, mass_bound_kg=2.5)
    assert low is not None and not low.proposition2_holds
    # too few samples: no estimate
    for k in range(HOVER_MIN_SAMPLES - 1):
        h.add(1, 10.0 + 0.1 * k, 0.5)
    assert h.estimate(1, 11.0, 20.0, 1.0, 2.0, None) is None


def test_attitude_mode_is_prepared_for_gcs_fly_and_simulated_by_gcs_sim(tmp_path):
    from gcs.sim.runner import SimOptions, simulate

    team = load_team(CONFIGS / "square4.yaml")
    setup = prepare(team, FlyOptions(out_dir=tmp_path, mode="attitude"))
    assert setup.mode == "attitude" and setup.tick_rate_hz == team.fly.attitude.tick_rate_hz
    assert setup.stability.startswith("attitude mode with alpha_p 1.5, c_p 0.6 at 100 Hz")
    assert (setup.gains.alpha_p, setup.gains.c_p) == (1.5, 0.6)
    # gcs sim flies it on its onboard attitude loop (gcs/sim/loop.py), holding Jhat
    log = simulate(team, SimOptions(mode="attitude", duration_s=0.5)).log
    assert log.extra["mode"] == "attitude" and not log.extra["estimates"]["inertia_estimated"]
    assert np.isfinite(log.position_enu_m).all()


_KERNELS_AFTER_SETUP = """
import sys, tempfile
from pathlib import Path
import numpy as np
from flightkit import jitcache
jitcache.configure()
from gcs.fly.flight import Flight
from gcs.fly.setup import FlyOptions, prepare
from gcs.config import load_team
from gcs.control import predict
from gcs import metrics

with tempfile.TemporaryDirectory() as tmp:
    options = FlyOptions(out_dir=Path(tmp))
    flight = Flight(prepare(load_team(sys.argv[1]), options), options)
    kernels = (predict._reached, metrics.formation_error_m, metrics._formation_errors)
    before = [len(k.signatures) for k in kernels]
    # what a formation tick and the records at the end run, with the tick's own array types
    n = flight.n
    rng = np.random.default_rng(0)
    p, v, t = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.random(n)
    r, w = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    audit = predict.PredictionAudit(n)
    audit.observe(p, v, t, r, w, t)
    metrics.formation_error_m(p, flight.tick.offsets_m)
    metrics.formation_error(rng.normal(size=(30, n, 3)), flight.tick.offsets_m)
    print(before, [len(k.signatures) for k in kernels])
"""


def test_the_flight_compiles_the_kernels_its_ticks_run_before_any_link_opens():
    # a new machine's first flight compiled the prediction audit's kernel in its first formation
    # tick: 0.5 s and more on a loaded machine, every link read as lost, the formation stopped.
    # In a new process (numba's compiled signatures are per process): after the Flight is built,
    # what the ticks and the records run compiles nothing more
    import subprocess
    import sys

    team = Path(__file__).resolve().parents[2] / "configs" / "square4.yaml"
    out = subprocess.run([sys.executable, "-c", _KERNELS_AFTER_SETUP, str(team)],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    before, after = out.strip().splitlines()[-1].split("] [")
    assert before.strip("[") == after.strip("]"), out
    assert "0" not in before.strip("[").split(", "), out


@pytest.mark.parametrize(("mode", "estimated"),
                         [("rates", False), ("attitude", False), ("actuators", True)])
def test_the_flight_integrates_jhat_only_where_it_sends_the_torque(tmp_path, mode, estimated):
    # GIVEN the demo team prepared for `mode` (mhat(0) from the hover: fly.initial_mass)
    team = load_team(CONFIGS / "square4.yaml")
    options = FlyOptions(out_dir=tmp_path, mode=mode)
    flight = Flight(prepare(team, options), options)
    j0 = team.initial_inertia_estimates_kgm2()
    # WHEN its law ticks for 1 s with the vehicles out of formation, tilted and turning
    rot = np.tile(rotation_from_rpy(0.1, -0.05, 0.2), (4, 1, 1))
    meas = TeamMeasurement(team.initial_positions_enu_m(), np.full((4, 3), 0.3),
                           np.zeros((4, 3)), rot, np.full((4, 3), 0.2))
    ref = reference_velocity(0.0, *team.reference_velocity.as_arrays())
    for _ in range(int(flight.setup.tick_rate_hz)):
        command = flight.law.step(meas, ref, flight.period_s)
    # THEN Jhat moved only where the torque (26) is the setpoint; rates and attitude mode hold
    # it at Jhat(0), and so does what the records get
    moved = np.abs(flight.law.rhohat - j0).max()
    assert (moved > 1e-3) if estimated else (moved == 0.0)
    if not estimated:
        np.testing.assert_array_equal(command.inertia_estimate_kgm2, j0)
    # AND the records say where each estimate started and whether Jhat was estimated
    n = team.n
    flight.figures.builder.append(t_s=0.0, position_enu_m=meas.position_m, velocity_enu_mps=np.zeros((n, 3)),
                          reference_velocity_enu_mps=np.zeros(3), attitude_error=np.zeros(n),
                          omega_error_radps=np.zeros(n), mass_estimate_kg=np.ones(n),
                          inertia_estimate_kgm2=j0, thrust_n=np.ones(n),
                          force_enu_n=np.zeros((n, 3)))
    log = flight.figures.builder.build()
    assert log.extra["mode"] == mode
    assert log.extra["estimates"] == {"mass_from": ["hover"] * n, "inertia_from": "team",
                                      "inertia_kgm2": j0.tolist(), "inertia_estimated": estimated}


# --- position mode: the baseline (gcs/control/slots.py) ---------------------------------------


def test_position_mode_is_prepared_without_law_criterion_or_hover_estimate():
    # GIVEN Scenario I (fly.initial_mass from_hover, a delay compensation, the law's gains)
    team = load_team(CONFIGS / "square4.yaml")
    setup = prepare(team, FlyOptions(out_dir=OUT, mode="position"))
    # THEN it flies position mode at fly.position's rate, with no law ("autopilot")
    assert (setup.mode, setup.law, setup.tick_rate_hz) == ("position", "autopilot", 50.0)
    assert setup.mode_choice == "mode position (--mode)" and setup.log_every == 1
    # AND asks only for what the slots and the safety rules read: no IMU (no u', u''), no
    # ATTITUDE_TARGET (no mhat(0) from the hover), hence no longer PRIME for it
    assert setup.requested_rates_hz == {"ATTITUDE_QUATERNION": 50.0, "LOCAL_POSITION_NED": 50.0,
                                        "EXTENDED_SYS_STATE": 5.0}
    assert setup.plan.prime_s == 1.5 and setup.plan.control_mode == "position"
    assert not any(v.estimates.from_hover for v in setup.team.vehicles)
    # AND no loop criterion refuses a vehicle or judges its link delay
    assert setup.plan.rules.loop_refusals == {} and setup.delay_judge is None
    assert setup.stability.startswith("position mode: no law runs on the ground station")
    # AND the file's fly.mode may choose it too; a --controller makes no sense with it
    chosen = prepare(_with_fly(team, control_mode="position"), FlyOptions(out_dir=OUT))
    assert (chosen.mode, chosen.mode_choice) == ("position", "mode position (fly.mode)")
    with pytest.raises(FlightSetupError, match=r"^--controller baseline: position mode runs no "
                                               r"law"):
        prepare(team, FlyOptions(out_dir=OUT, mode="position", law="baseline"))


def test_the_px4_sih_team_file_flies_the_sitl_ports_with_the_docs_defaults():
    # GIVEN the shipped team file for four PX4 SIH SITL vehicles
    team = load_team(CONFIGS / "square4_px4sih.yaml")
    # THEN each vehicle i talks to PX4's instance i-1 on its default ports, from the ground,
    # settling at the default go-to-start tolerance, with the mass from the hover
    assert [(v.link.local_port, v.link.remote_port) for v in team.vehicles] == [
        (14540 + i, 14580 + i) for i in range(4)]
    assert team.fly.start == "takeoff" and team.fly.go_to_start.tolerance_m == 0.3
    # AND gcs fly takes it as it is: rates at the declared 10 ms
    assert prepare(team, FlyOptions(out_dir=OUT)).mode == "rates"


@pytest.mark.parametrize("config", ["square4.yaml", "square4_massdrop.yaml", "grid16.yaml",
                                    "square4_px4sih.yaml"])
@pytest.mark.parametrize("delay_s", [0.0, 0.01, 0.05, 0.1, 0.2, 1.0])
def test_fly_mode_auto_never_picks_position(config, delay_s):
    # GIVEN a shipped team at a declared link delay from none to one where no law mode passes
    team = _with_fly(load_team(CONFIGS / config), link_delay_s=delay_s)
    # THEN auto flies one of the law's modes, never the baseline
    setup = prepare(team, FlyOptions(out_dir=OUT))
    assert setup.mode in ("rates", "attitude") and setup.law != "autopilot"
    assert "position" not in setup.mode_choice


def test_position_mode_records_no_law_and_no_estimates(tmp_path):
    # GIVEN a position-mode flight of Scenario I
    team = load_team(CONFIGS / "square4.yaml")
    options = FlyOptions(out_dir=tmp_path, mode="position")
    flight = Flight(prepare(team, options), options)
    # WHEN a record sample is taken without a law command
    from gcs.fly.measure import TeamSample

    n = team.n
    sample = TeamSample(np.asarray(team.initial_positions_enu_m(), dtype=float),
                        np.zeros((n, 3)), np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)),
                        np.zeros((n, 3)), np.zeros(n), np.zeros(n), np.ones(n, dtype=bool),
                        np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n))
    flight.tick.log(0.0, sample, np.array([0.3, 0.3, 0.2]), None)
    log = flight.figures.builder.build()
    # THEN the records say position mode, no law, nothing estimated (not estimates held at
    # their initial values), and the law's figures are unknown, not zero
    assert (log.controller, log.extra["mode"]) == ("autopilot", "position")
    assert log.extra["estimates"] == {"mass_from": ["none"] * n, "inertia_from": "none",
                                      "inertia_kgm2": None, "inertia_estimated": False}
    assert log.extra["gains"] is None and log.extra["derivative"] is None
    for series in (log.mass_estimate_kg, log.thrust_n, log.attitude_error,
                   log.inertia_estimate_kgm2, log.force_enu_n):
        assert np.isnan(series).all()
    # AND the formation error is still measured: 7.07 m at the starts, between p - theta of
    # vehicles 1 and 3, (2, 2, 9) and (-3, -2, 12)
    assert flight.tick.formation_error_m == pytest.approx(math.sqrt(50.0), abs=1e-9)
    np.testing.assert_array_equal(log.mass_true_kg[0], team.true_masses_kg())
