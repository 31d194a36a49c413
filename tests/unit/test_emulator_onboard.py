"""The calibrated personalities' onboard pieces against closed forms: filters, the seeded noise,
the exact second-order step, PX4's rate control, the reference model (acceleration limit,
delay), and what they do inside the plant (output delay, drag, damping, thrust scale, sample
times, a nominal vehicle untouched by calibrated neighbours)."""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import expm

from flightkit.physics import GRAVITY_MPS2
from vehicle_emulator.calibration.replay import sitl_airframe
from vehicle_emulator.config.personality import PERSONALITIES, Dynamics, RateLoop, Sensors
from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.physics import fleet_arrays as fa
from vehicle_emulator.physics import sensors as sn
from vehicle_emulator.physics.inner import (
    PX4_I_FACTOR_RADPS,
    px4_rate_control,
    reference_rate_control,
    second_order_step,
)
from vehicle_emulator.physics.plant import ControlMode, FleetPlant


def _response(coef, f_hz, fs_hz):
    """|H(e^{j w})| of a biquad (b0, b1, b2, a1, a2) at f_hz."""
    z = cmath.exp(-2j * math.pi * f_hz / fs_hz)
    b0, b1, b2, a1, a2 = coef
    return abs((b0 + b1 * z + b2 * z * z) / (1 + a1 * z + a2 * z * z))


@pytest.mark.parametrize("fc, fs", [(40.0, 250.0), (20.0, 500.0), (30.0, 250.0)])
def test_biquad_is_a_butterworth_low_pass_with_unit_dc_gain(fc, fs):
    coef = sn.biquad_coefficients(fc, fs)
    # THEN DC gain 1, -3 dB at the cutoff (prewarped), and it attenuates above
    assert _response(coef, 0.0, fs) == pytest.approx(1.0, abs=1e-12)
    assert _response(coef, fc, fs) == pytest.approx(1 / math.sqrt(2), abs=1e-9)
    assert _response(coef, 2 * fc, fs) < 0.3
    # and stepping it with a constant converges to the constant; a primed state starts there
    state = np.zeros(2)
    y = [sn.biquad(np.array(coef), state, 1.0) for _ in range(200)]
    assert y[-1] == pytest.approx(1.0, abs=1e-9)
    primed = np.zeros(2)
    sn.biquad_prime(np.array(coef), primed, 9.81)
    assert sn.biquad(np.array(coef), primed, 9.81) == pytest.approx(9.81, abs=1e-12)


def test_biquad_passes_through_without_a_cutoff_or_above_nyquist():
    assert sn.biquad_coefficients(0.0, 250.0) == sn.PASS_THROUGH
    assert sn.biquad_coefficients(200.0, 250.0) == sn.PASS_THROUGH
    assert sn.one_pole_alpha(0.0, 0.004) == 1.0
    assert sn.one_pole_alpha(2.0, 0.004) == pytest.approx(0.004 / (0.004 + 1 / (4 * math.pi)))


def test_noise_streams_are_standard_normal_and_seeded_per_sysid():
    def draws(seed, sysid, n=20000):
        rng = np.array([sn.noise_seed(seed, sysid)], dtype=np.uint64)
        return np.array([sn.gauss_pair(rng, 0) for _ in range(n // 2)]).ravel()

    a = draws(0, 1)
    assert abs(a.mean()) < 0.03 and abs(a.std() - 1.0) < 0.02
    assert abs(np.corrcoef(a[:-1], a[1:])[0, 1]) < 0.03
    np.testing.assert_array_equal(a, draws(0, 1))
    assert not np.array_equal(a[:100], draws(0, 2)[:100])
    assert not np.array_equal(a[:100], draws(1, 1)[:100])


@pytest.mark.parametrize("wn, zeta, dt", [(8.48, 0.79, 0.002), (250.0, 1.4, 0.002),
                                          (10.0, 1.0, 0.004)])
def test_second_order_step_is_the_exact_zero_order_hold_discretisation(wn, zeta, dt):
    phi, gamma = second_order_step(wn, zeta, dt)
    a = np.array([[0.0, 1.0], [-wn * wn, -2 * zeta * wn]])
    m = expm(np.block([[a, np.array([[0.0], [wn * wn]])], [np.zeros((1, 3))]]) * dt)
    np.testing.assert_allclose(np.array(phi).reshape(2, 2), m[:2, :2], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(gamma, m[:2, 2], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="wn, zeta, dt > 0"):
        second_order_step(wn, 0.0, dt)


NO_LIMIT = np.zeros((1, 3))  # the mixer made every axis's torque (physics.rotors_from_wrench_into)


def _px4_gains(n=1):
    d = PERSONALITIES["px4"].dynamics
    return fa.Px4RateGains(
        gain_p=np.tile(d.rate_p, (n, 1)), gain_i=np.tile(d.rate_i, (n, 1)),
        gain_d=np.tile(d.rate_d, (n, 1)), int_limit=np.tile(d.rate_int_limit, (n, 1)),
        yaw_alpha=np.ones(n), accel_per_unit_radps2=np.tile(d.accel_per_unit_radps2, (n, 1)),
    )


def _loops(rate_sp, rate_int):
    """One vehicle's LoopState with the rate setpoint and integral given (the rest unused)."""
    z = np.zeros((1, 3))
    return fa.LoopState(np.eye(3)[None].copy(), np.asarray(rate_sp, dtype=float), np.zeros(1),
                     z.copy(), rate_int, z.copy(), z.copy())


def _imu(rate_meas=None, gyro_raw=None):
    """One vehicle's ImuState with the filtered and raw gyro given (zeros otherwise)."""
    z = np.zeros((1, 3))
    return fa.ImuState(np.zeros((1, 3, 2)), np.zeros((1, 3, 2)), np.zeros((1, 3, 2)),
                    z.copy() if gyro_raw is None else gyro_raw, z.copy(),
                    z.copy() if rate_meas is None else rate_meas, z.copy(), z.copy(), z.copy())


def _outputs(torque_out, yaw_lpf, limited):
    return fa.RateOutputs(torque_out, yaw_lpf, limited, np.zeros((1, 3)), np.zeros(1))


def test_px4_rate_control_is_pids_normalised_torque_times_authority():
    # GIVEN a rate error of (0.5, -0.2, 0.1) rad/s, no integral, no derivative, yaw filter open
    g = _px4_gains()
    sp, meas = np.array([[0.5, -0.2, 0.1]]), np.zeros((1, 3))
    integ, yaw, out = np.zeros((1, 3)), np.zeros(1), np.zeros((1, 3))
    inertia = np.array([[0.025, 0.025, 0.030]])
    px4_rate_control(0, _loops(sp, integ), _imu(meas), g, inertia, _outputs(out, yaw, NO_LIMIT),
                     False, 0.004)
    # THEN torque = J * accel_per_unit * P e (the integral only counts from the next call)
    np.testing.assert_allclose(out[0], inertia[0] * g.accel_per_unit_radps2[0] * g.gain_p[0]
                               * sp[0])
    # and the integral grew by i_factor * I e dt
    f = 1 - (sp[0] / PX4_I_FACTOR_RADPS) ** 2
    np.testing.assert_allclose(integ[0], f * g.gain_i[0] * sp[0] * 0.004)
    # WHEN the error is huge THEN the output clips at 1 (normalised) and the integral at its limit
    integ[:] = 0.29
    px4_rate_control(0, _loops([[50.0, 50.0, 50.0]], integ), _imu(meas), g, inertia,
                     _outputs(out, yaw, NO_LIMIT), False, 1.0)
    np.testing.assert_allclose(out[0], inertia[0] * g.accel_per_unit_radps2[0])
    assert np.all(integ[0] <= g.int_limit[0] + 1e-12)
    # and landed, the integral does not move
    before = integ.copy()
    px4_rate_control(0, _loops(sp, integ), _imu(meas), g, inertia, _outputs(out, yaw, NO_LIMIT),
                     True, 0.004)
    np.testing.assert_array_equal(integ, before)


def test_px4_yaw_torque_goes_through_a_first_order_low_pass():
    alpha = sn.one_pole_alpha(2.0, 0.004)
    g = _px4_gains()._replace(yaw_alpha=np.array([alpha]))
    g.gain_i[:] = 0.0
    yaw, out = np.zeros(1), np.zeros((1, 3))
    inertia = np.array([[0.025, 0.025, 0.030]])
    seen = []
    for _ in range(50):
        px4_rate_control(0, _loops([[0.0, 0.0, 1.0]], np.zeros((1, 3))), _imu(), g, inertia,
                         _outputs(out, yaw, NO_LIMIT), False, 0.004)
        seen.append(out[0, 2])
    full = inertia[0, 2] * g.accel_per_unit_radps2[0, 2] * g.gain_p[0, 2]
    k = np.arange(1, 51)
    np.testing.assert_allclose(seen, full * (1 - (1 - alpha) ** k), rtol=1e-12)


def test_px4_integral_never_winds_further_into_a_saturation_the_mixer_reports():
    # GIVEN rate errors of +0.5 on every axis, roll saturated positive (the mixer made less
    # than asked), pitch negative, yaw free
    g = _px4_gains()
    inertia = np.array([[0.025, 0.025, 0.030]])
    limited = np.array([[1.0, -1.0, 0.0]])
    integ, out = np.full((1, 3), 0.05), np.zeros((1, 3))
    for sp in ([[0.5, 0.5, 0.5]], [[-0.5, -0.5, -0.5]]):
        before = integ.copy()
        px4_rate_control(0, _loops(sp, integ), _imu(), g, inertia,
                         _outputs(out, np.zeros(1), limited), False, 0.004)
        step = integ[0] - before[0]
        # THEN the roll integral does not grow positive, nor pitch negative; yaw integrates
        if sp[0][0] > 0:
            assert step[0] == 0.0 and step[1] > 0.0 and step[2] > 0.0
        else:
            assert step[0] < 0.0 and step[1] == 0.0 and step[2] < 0.0


_STILL = fa.Body(np.zeros((1, 3)), np.zeros((1, 3)), np.eye(3)[None].copy(), np.zeros((1, 3)))


def test_reference_model_integral_only_shrinks_on_a_saturated_axis():
    # GIVEN ArduPilot's tracking loop with a positive integral on every axis and the body not
    # turning, so the tracking error keeps the sign of the command
    gains, delay_buf, delay_idx = _reference_arrays()
    for cmd, shrinks in (((0.5, 0.5, 0.5), False), ((-0.5, -0.5, -0.5), True)):
        st_int = np.full((1, 3), 1.0)
        ref = np.zeros((1, 3, 2))
        ref[0, :, 0] = cmd  # the reference already at the command: error = cmd - 0
        st = fa.ReferenceState(np.array([cmd], dtype=float), ref, np.zeros((1, 3)), st_int,
                            delay_buf, delay_idx)
        reference_rate_control(0, _loops([cmd], np.zeros((1, 3))), _imu(), _STILL, gains, st,
                               np.array([[0.023, 0.023, 0.046]]),
                               _outputs(np.zeros((1, 3)), np.zeros(1),
                                        np.array([[0.0, 1.0, -1.0]])), False, 0.002)
        # THEN the free axis integrates either way; a limited one (either sign: ArduPilot's
        # flags are per axis) only when that shrinks the integral
        assert bool(st_int[0, 0] > 1.0) is (not shrinks) and bool(st_int[0, 0] < 1.0) is shrinks
        if shrinks:
            assert st_int[0, 1] < 1.0 and st_int[0, 2] < 1.0
        else:
            assert st_int[0, 1] == 1.0 and st_int[0, 2] == 1.0


def _reference_arrays(accel=(19.2, 19.2, 4.7), delay=(0, 0, 0), wn=300.0, zeta=1.0, dt=0.002):
    """(ReferenceGains, delay_buf, delay_idx) of one vehicle."""
    phi, gamma = second_order_step(wn, zeta, dt)
    gains = fa.ReferenceGains(
        accel_max_radps2=np.array([accel]), ref_gain=np.ones((1, 3)),
        ref_phi=np.tile(phi, (1, 3, 1)), ref_gamma=np.tile(gamma, (1, 3, 1)),
        angle_p=np.zeros((1, 3)), track=np.array([[40.0, 200.0]]), delay_periods=np.array([delay]),
    )
    return gains, np.zeros((1, 3, 32)), np.zeros(1, int)


def _reference_run(arr, cmd, steps, dt=0.002):
    gains, delay_buf, delay_idx = arr
    st = fa.ReferenceState(np.zeros((1, 3)), np.zeros((1, 3, 2)), np.zeros((1, 3)),
                        np.zeros((1, 3)), delay_buf, delay_idx)
    out, shaped, ref = np.zeros((1, 3)), [], []
    loops = _loops([cmd], np.zeros((1, 3)))
    for _ in range(steps):
        reference_rate_control(0, loops, _imu(), _STILL, gains, st,
                               np.array([[0.023, 0.023, 0.046]]),
                               _outputs(out, np.zeros(1), NO_LIMIT), False, dt)
        shaped.append(st.shaped_radps[0].copy())
        ref.append(st.ref[0, :, 0].copy())
    return np.array(shaped), np.array(ref)


def test_reference_model_slews_at_the_acceleration_limit():
    # GIVEN ArduPilot's limits WHEN 0.5 / 0.5 / 1.0 rad/s are commanded
    shaped, _ = _reference_run(_reference_arrays(), (0.5, 0.5, 1.0), 150)
    # THEN the shaped command ramps at 19.2 and 4.7 rad/s^2 and stops at the command
    steps = np.diff(np.vstack([np.zeros(3), shaped]), axis=0)
    assert np.all(steps[:, 0] <= 19.2 * 0.002 + 1e-12) and np.all(steps[:, 2] <= 4.7 * 0.002 + 1e-12)
    assert shaped[12, 0] == pytest.approx(13 * 19.2 * 0.002)
    np.testing.assert_allclose(shaped[-1], (0.5, 0.5, 1.0))
    assert np.argmax(shaped[:, 2] >= 1.0) == math.ceil(1.0 / (4.7 * 0.002)) - 1


def test_reference_model_delay_line_shifts_the_response_by_whole_periods():
    _, plain = _reference_run(_reference_arrays(), (0.5, 0.0, 0.0), 60)
    _, late = _reference_run(_reference_arrays(delay=(5, 0, 0)), (0.5, 0.0, 0.0), 60)
    np.testing.assert_allclose(late[5:, 0], plain[:-5, 0], atol=1e-12)
    assert np.all(late[:5, 0] == 0.0)


def _sih(n=1, autopilot="px4", **kw):
    return [replace(s, **kw) for s in sitl_airframe(autopilot, n, 5.0)]


def test_px4_motors_get_the_rate_loops_output_one_control_period_late():
    # GIVEN the px4 personality hovering in rates mode, noise off
    p = FleetPlant(_sih())
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    p.step(8)  # two control periods, on the 4 ms grid
    # WHEN a roll rate is commanded THEN the torque reaching the mixer changes one period later
    p.rate_cmd_flu_radps[0, 0] = 0.5
    p.step(1)
    assert np.all(p.torque_sp_nm[0] == 0.0) and p.onboard.torque_next_nm[0, 0] > 0.0
    p.step(3)
    assert np.all(p.torque_sp_nm[0] == 0.0)
    p.step(1)
    assert p.torque_sp_nm[0, 0] > 0.0


def test_linear_drag_and_angular_damping_decay_as_exponentials():
    # GIVEN the px4 personality (SIH_KDV / SIH_MASS 1/s, SIH_KDW / I 1/s roll) without motor lag
    p = FleetPlant(_sih(motor_time_constant_s=0.0))
    p.mode[:] = ControlMode.OFF
    p.omega_flu_radps[0] = (1.0, 0.0, 0.0)
    p.step(1000)
    # THEN falling: v = -(g / k)(1 - e^{-k t}); rolling: w = w0 e^{-k t}
    assert p.velocity_enu_mps[0, 2] == pytest.approx(-GRAVITY_MPS2 * (1 - math.exp(-1.0)),
                                                     rel=1e-3)
    assert p.omega_flu_radps[0, 0] == pytest.approx(math.exp(-1.0), rel=1e-3)
    # and the accelerometer feels the drag: specific force = R^T (-k v), here k = 1/s
    np.testing.assert_allclose(p.specific_force_flu_mps2[0],
                               p.rotation[0].T @ -p.velocity_enu_mps[0], rtol=1e-9)


def test_ardupilot_thrust_scale_is_its_battery_and_air_density_compensation():
    p = FleetPlant(_sih(autopilot="ardupilot"))
    scale = PERSONALITIES["ardupilot"].dynamics.thrust_scale
    assert scale == pytest.approx(0.39 / 0.3649)
    # THEN hover needs m g / (4 f_max scale) = 0.365 for the SITL airframe, as recorded
    assert p.hover_thrust_norm[0] == pytest.approx(3.0 * GRAVITY_MPS2 / (4 * 18.86 * scale))
    assert p.hover_thrust_norm[0] == pytest.approx(0.3649, abs=0.002)
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = 0.5
    p.step(100)
    assert p.thrust_n[0] == pytest.approx(0.5 * 4 * 18.86 * scale, rel=1e-3)


def test_px4_estimates_carry_sample_times_on_the_4_ms_grid_position_one_sample_older():
    p = FleetPlant(_sih())
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    p.step(1003)
    att, pos = p.sample_time_s()
    assert att[0] == pytest.approx(1.000) and pos[0] == pytest.approx(0.996)
    # a nominal vehicle reports now
    q = FleetPlant([replace(default_vehicle(1, on_ground=False), autopilot="nominal")])
    q.step(1003)
    assert q.sample_time_s()[0][0] == q.sample_time_s()[1][0] == q.time_s


def test_px4_imu_noise_sizes_per_sample_and_two_sample_means():
    # GIVEN SIH's gyro noise per 4 ms sample, HIGHRES_IMU as two-sample means, 40 Hz rate filter
    p = FleetPlant(_sih())
    p.onboard.noise_on[:] = True
    p.mode[:] = ControlMode.IDLE  # motors on, no control: the noise alone
    g, r = [], []
    for _ in range(4000):
        p.step(4)
        g.append(p.onboard.gyro_imu_flu_radps[0].copy())
        r.append(p.onboard.rate_meas_flu_radps[0].copy())
    sigma = np.array(PERSONALITIES["px4"].sensors.gyro_noise_std_radps)
    # THEN the means carry sigma / sqrt(2); the filtered rate less (the recorded 0.085 for 0.14)
    np.testing.assert_allclose(np.std(g, axis=0), sigma / math.sqrt(2), rtol=0.06)
    ratio = np.std(r, axis=0) / sigma
    assert np.all((ratio > 0.5) & (ratio < 0.7))


def test_a_nominal_vehicle_is_untouched_by_calibrated_neighbours():
    nominal = replace(default_vehicle(1, on_ground=False), autopilot="nominal")
    alone = FleetPlant([nominal])
    mixed = FleetPlant([nominal, *(_sih(2)[1:]), *_sih(1, autopilot="ardupilot")])
    mixed.onboard.noise_on[1:] = True
    for p in (alone, mixed):
        p.mode[:] = ControlMode.RATES
        p.thrust_cmd_norm[:] = p.hover_thrust_norm
        p.rate_cmd_flu_radps[:] = (0.3, -0.2, 0.5)
        p.step(3000)
    np.testing.assert_array_equal(alone.rotation[0], mixed.rotation[0])
    np.testing.assert_array_equal(alone.position_enu_m[0], mixed.position_enu_m[0])


def test_personality_consistency_is_checked():
    broken = replace(PERSONALITIES["px4"], sensors=Sensors())
    with pytest.raises(ValueError, match="calibrated rate loop needs the sensor model"):
        FleetPlant(_sih(), personalities=[broken])
    assert Dynamics().rate_loop is RateLoop.NOMINAL


@pytest.mark.parametrize("f_hz, zeta, dt", [(23.4, 0.05, 0.002), (5.0, 0.2, 0.004)])
def test_disturbance_resonator_has_unit_std_a_peak_at_its_frequency_and_no_dc(f_hz, zeta, dt):
    a1, a2, gain = sn.resonator_coefficients(f_hz, zeta, dt)
    rng = np.random.default_rng(3)
    state = np.zeros(3)
    y = np.array([sn.resonator_step(np.array([a1, a2, gain]), state, w)
                  for w in rng.standard_normal(200_000)])
    # THEN the stationary std is 1, the spectrum peaks at the frequency, and its mean is 0
    assert np.std(y) == pytest.approx(1.0, rel=0.03)
    spectrum = np.abs(np.fft.rfft(y)) ** 2
    freqs = np.fft.rfftfreq(y.size, dt)
    smooth = np.convolve(spectrum, np.ones(201) / 201, mode="same")
    assert freqs[np.argmax(smooth)] == pytest.approx(f_hz, rel=0.05)
    # the zero at DC: the band below a tenth of the frequency holds almost no power
    assert smooth[freqs < 0.1 * f_hz].mean() < 1e-3 * smooth.max()
    # white when no frequency is given
    assert sn.resonator_coefficients(0.0, zeta, dt) == (0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="Nyquist"):
        sn.resonator_coefficients(0.6 / dt, zeta, dt)


def test_complementary_attitude_error_is_the_gyro_noise_integrated_and_forgotten():
    # GIVEN one vehicle whose gyro noise is a known white sequence, tau 2 s at 250 Hz
    dt, tau, sigma = 0.004, 2.0, 0.1
    phi = np.array([[math.exp(-dt / tau), -1.0, math.exp(-dt / tau)]])
    rng = np.random.default_rng(5)
    err = np.zeros((1, 3))
    omega = np.array([[0.3, -0.2, 0.1]])
    out = []
    for _ in range(100_000):
        raw = omega + sigma * rng.standard_normal((1, 3))
        sn.gyro_integration_errors(0, dt, np.array([True]), phi, raw, omega, err)
        out.append(err[0].copy())
    out = np.array(out)
    # THEN the error is the AR(1) of the noise times dt: std sigma dt / sqrt(1 - phi^2); an
    # axis that is off stays 0, and no noise means no error
    expected = sigma * dt / math.sqrt(1.0 - phi[0, 0] ** 2)
    assert np.std(out[:, 0]) == pytest.approx(expected, rel=0.1)
    assert np.std(out[:, 2]) == pytest.approx(expected, rel=0.1)
    assert np.all(out[:, 1] == 0.0)
    sn.gyro_integration_errors(0, dt, np.array([False]), phi, raw, omega, err)
    assert np.all(err == 0.0)


def test_gyro_bias_wanders_in_highres_imu_only():
    # GIVEN an ardupilot vehicle hovering noise-on in rates mode
    p = FleetPlant(sitl_airframe("ardupilot"))
    p.onboard.noise_on[:] = True
    p.mode[:] = ControlMode.RATES
    p.thrust_cmd_norm[:] = p.hover_thrust_norm
    diff = []
    for _ in range(3000):
        p.step(2)
        diff.append(p.onboard.gyro_imu_flu_radps[0] - p.onboard.rate_meas_flu_radps[0])
    diff = np.array(diff)
    # THEN HIGHRES_IMU differs from the (bias-free) rate the loop flies on by the bias, whose
    # std is the configured one's order, on z largest (SITL's z drift)
    bias = np.array(PERSONALITIES["ardupilot"].sensors.gyro_bias_std_radps)
    assert np.all(np.std(diff, axis=0) > 0.2 * bias)
    assert np.all(np.std(diff, axis=0) < 2.0 * bias)
    assert np.argmax(np.std(diff, axis=0)) == 2


@pytest.mark.parametrize("order", [1, 2])
def test_attitude_estimate_errors_are_gauss_markov_of_their_order(order):
    # GIVEN one vehicle's yaw estimate error of 1 sigma 0.05 rad, tau 0.5 s, first or second
    # order, advanced every 10 ms for 2000 s
    dt, tau, std, steps = 0.01, 0.5, 0.05, 200_000
    phi = math.exp(-dt / tau)
    att_std = np.array([[0.0, 0.0, std]])
    att_phi = np.full((1, 3), phi)
    smooth = np.array([[0.0, 0.0, sn.smooth_gain(phi) if order == 2 else 0.0]])
    zeros = np.zeros((1, 3))
    stage, err = np.zeros((1, 3)), np.zeros((1, 3))
    vel_parts, vel_err, pos_err = np.zeros((1, 2, 3)), np.zeros((1, 3)), np.zeros((1, 3))
    rng = np.array([sn.noise_seed(3, 1)])
    yaw = np.empty(steps)
    for s in range(steps):
        sn.estimate_errors(0, dt, np.array([True]),
                           fa.EstimateNoise(att_std, att_phi, smooth, zeros, np.ones(1), zeros,
                                         np.ones(1), np.ones(1), np.ones(1)),
                           rng, fa.EstimateErrors(stage, err, vel_parts, vel_err, pos_err))
        yaw[s] = err[0, 2]
    # THEN its std is the stated one and its autocorrelation at lag tau is exp(-1) (first
    # order) or 2 exp(-1) (second order: (1 + w/tau) exp(-w/tau)); the other axes stay at 0
    lag = int(round(tau / dt))
    rho = np.corrcoef(yaw[:-lag], yaw[lag:])[0, 1]
    assert np.std(yaw) == pytest.approx(std, rel=0.1)
    assert rho == pytest.approx(order * math.exp(-1.0), abs=0.05)
    assert not err[0, :2].any()


def test_velocity_error_is_a_fast_error_plus_a_slow_drift_kept_out_of_the_position():
    # GIVEN one vehicle's velocity error: a fast part (north 0.1 m/s, 0.5 s) and a slow drift
    # (north 0.15 m/s, 20 s), none in the position (share 0), advanced every 10 ms for 4000 s
    dt, steps = 0.01, 400_000
    fast_std, fast_tau, drift_std, drift_tau = 0.1, 0.5, 0.15, 20.0
    zeros = np.zeros((1, 3))
    vel_std, drift = np.array([[fast_std, 0.0, 0.0]]), np.array([[drift_std, 0.0, 0.0]])
    phis = np.array([math.exp(-dt / fast_tau)]), np.array([math.exp(-dt / drift_tau)])
    stage, err = np.zeros((1, 3)), np.zeros((1, 3))
    vel_parts, vel_err, pos_err = np.zeros((1, 2, 3)), np.zeros((1, 3)), np.zeros((1, 3))
    rng = np.array([sn.noise_seed(5, 1)])
    north = np.empty(steps)
    slow = np.empty(steps)
    for s in range(steps):
        sn.estimate_errors(0, dt, np.array([True]),
                           fa.EstimateNoise(zeros, np.ones((1, 3)), zeros, vel_std, phis[0], drift,
                                         phis[1], np.ones(1), np.zeros(1)),
                           rng, fa.EstimateErrors(stage, err, vel_parts, vel_err, pos_err))
        north[s], slow[s] = vel_err[0, 1], vel_parts[0, 1, 1]  # ENU: north is y
    # THEN the error is the sum of the two, its variance theirs added, the drift's
    # autocorrelation at its tau exp(-1), and the position, east and up carry none of it
    lag = int(round(drift_tau / dt))
    assert np.std(north) == pytest.approx(math.hypot(fast_std, drift_std), rel=0.15)
    assert np.std(slow) == pytest.approx(drift_std, rel=0.2)
    assert np.corrcoef(slow[:-lag], slow[lag:])[0, 1] == pytest.approx(math.exp(-1.0), abs=0.1)
    assert vel_err[0, 1] == pytest.approx(vel_parts[0, 0, 1] + vel_parts[0, 1, 1])
    assert not pos_err.any() and vel_err[0, 0] == 0.0 and vel_err[0, 2] == 0.0


def test_px4_heading_error_size_follows_the_time_since_each_takeoff():
    # GIVEN a px4 and an ardupilot vehicle on the ground (the px4 personality schedules its
    # heading error's size; ardupilot's is stationary)
    specs = sitl_airframe("px4", 1, 0.0) + [
        replace(sitl_airframe("ardupilot", 1, 0.0)[0], vehicle_id=2, sysid=2)]
    plant = FleetPlant(specs, dt_s=1e-3)
    ob = plant.onboard
    s = PERSONALITIES["px4"].sensors
    base, floor = s.attitude_error_std_rad[2], s.heading_floor_rad
    ardupilot = PERSONALITIES["ardupilot"].sensors.attitude_error_std_rad[2]
    ground, air = np.array([True, True]), np.array([False, False])
    # WHEN the time since takeoff passes through its phases
    ob.schedule_heading(5.0, ground)
    on_ground = ob.attitude_error_std[:, 2].copy()
    ob.schedule_heading(10.0, air)  # takeoff at 10 s
    ob.schedule_heading(10.0 + 0.5 * s.heading_takeoff_s, air)
    early = ob.attitude_error_std[:, 2].copy()
    ob.schedule_heading(10.0 + s.heading_takeoff_s + s.heading_settle_s, air)
    settling = ob.attitude_error_std[:, 2].copy()
    ob.schedule_heading(200.0, ground)  # landed
    ob.schedule_heading(300.0, air)  # the second takeoff
    ob.schedule_heading(301.0, air)
    again = ob.attitude_error_std[:, 2].copy()
    # THEN px4's 1 sigma is the floor on the ground, factor x base in the first phase, one time
    # constant into the settling floor + (base - floor) / e, and a takeoff starts it again;
    # ardupilot's never moves
    assert on_ground[0] == pytest.approx(floor)
    assert early[0] == pytest.approx(s.heading_takeoff_factor * base)
    assert settling[0] == pytest.approx(floor + (base - floor) * math.exp(-1.0))
    assert again[0] == pytest.approx(s.heading_takeoff_factor * base)
    for size in (on_ground, early, settling, again):
        assert size[1] == ardupilot
