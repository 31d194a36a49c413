"""The calibrated personalities' onboard model: per-vehicle arrays and the control-period step.

``Onboard`` turns each vehicle's personality.Dynamics and personality.Sensors into the arrays
the plant kernel reads (no per-vehicle Python work per physics step) and holds the onboard
states: IMU filters, noise generators, rate-loop integrators, the reference model, estimate
errors and the latched estimates telemetry reports (with their sample steps). ``onboard_step``
is the step the fleet kernel (plant.py) takes each physics step for the vehicles whose rate loop
is not the nominal one: every control period an IMU sample (sensors.py), the estimates, the cascade
(inner.py) and the personality's rate loop; in between, the outputs hold.
Pure: no clock, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from vehicle_emulator.config.personality import Personality, RateLoop
from vehicle_emulator.physics import sensors as sn
from vehicle_emulator.physics.fleet_arrays import (
    Body,
    Commands,
    EstimateErrors,
    EstimateNoise,
    ImuModel,
    ImuState,
    OnboardParams,
    OnboardStates,
    Px4RateGains,
    RateOutputs,
    ReferenceGains,
    ReferenceState,
)
from vehicle_emulator.physics.inner import (
    attitude_control,
    position_control,
    px4_rate_control,
    reference_rate_control,
    second_order_step,
)

__all__ = ["REF_DELAY_MAX", "Onboard", "named_params", "named_states", "onboard_step"]

REF_DELAY_MAX = 32  # control periods of dead time the reference model can hold
# the heading error's scheduled size is updated at most this often (it changes over seconds)
HEADING_UPDATE_S = 0.05


class Onboard:
    """Arrays of n vehicles' onboard models (see the module docstring); ``plant`` gives the
    initial state (FleetPlant's arrays), dt and sysids."""

    def __init__(self, personalities: Sequence[Personality], plant: Any) -> None:
        n, dt = plant.n, plant.dt_s
        self.n = n
        self.sysid = plant.sysid
        self._params: OnboardParams | None = None
        self._states: OnboardStates | None = None
        self._plain: tuple[tuple, tuple] | None = None
        dyn = [p.dynamics for p in personalities]
        sen = [p.sensors for p in personalities]
        f = np.float64
        self.rate_loop = np.array([int(d.rate_loop) for d in dyn], dtype=np.int64)
        self.sensor_model = self.rate_loop != RateLoop.NOMINAL
        for p, d, se in zip(personalities, dyn, sen, strict=True):
            if (d.rate_loop != RateLoop.NOMINAL) != se.model:
                raise ValueError(f"personality {p.name}: a calibrated rate loop needs the "
                                 f"sensor model and the other way round")
        self.control_div = np.array(
            [max(1, round(d.control_period_s / dt)) for d in dyn], dtype=np.int64
        )
        rates = 1.0 / (self.control_div * dt)
        self.angular_damping_per_s = np.array([d.angular_damping_per_s for d in dyn], dtype=f)
        self.disturbance_std = np.array([d.disturbance_std_radps2 for d in dyn], dtype=f)
        self.linear_drag_per_s = np.array([d.linear_drag_per_s for d in dyn], dtype=f)
        self.drag_decay = np.exp(-self.linear_drag_per_s * dt)  # velocity factor per step
        self.thrust_scale = np.array([d.thrust_scale for d in dyn], dtype=f)
        self.noise_on = np.zeros(n, dtype=np.bool_)  # EMU_NOISE (autopilots/node.py syncs it)
        self.gyro_noise_std = np.array([se.gyro_noise_std_radps for se in sen], dtype=f)
        self.accel_noise_std = np.array([se.accel_noise_std_mps2 for se in sen], dtype=f)
        self.off_noise_std = np.array(
            [(se.gyro_noise_off_std_radps, se.accel_noise_off_std_mps2) for se in sen], dtype=f
        )
        def lowpass(cutoffs: list[float]) -> np.ndarray:
            return np.array(
                [sn.biquad_coefficients(c, r) for c, r in zip(cutoffs, rates, strict=True)],
                dtype=f,
            )

        self.gyro_coef = lowpass([se.gyro_cutoff_hz for se in sen])
        self.dterm_coef = lowpass([d.dterm_cutoff_hz for d in dyn])
        self.accel_coef = lowpass([se.accel_cutoff_hz for se in sen])
        self.imu_mode = np.array(
            [2 if se.imu_filtered else (1 if se.imu_average_samples >= 2 else 0) for se in sen],
            dtype=np.int64,
        )
        self.position_delay = np.array([se.position_delay_periods for se in sen], dtype=np.int64)
        self.output_delay = np.array([d.output_delay_periods for d in dyn], dtype=np.int64)
        self.rate_gain_p = np.array([d.rate_p for d in dyn], dtype=f)
        self.rate_gain_i = np.array([d.rate_i for d in dyn], dtype=f)
        self.rate_gain_d = np.array([d.rate_d for d in dyn], dtype=f)
        self.rate_int_limit = np.array([d.rate_int_limit for d in dyn], dtype=f)
        self.yaw_alpha = np.array(
            [sn.one_pole_alpha(d.yaw_torque_cutoff_hz, 1.0 / r)
             for d, r in zip(dyn, rates, strict=True)],
            dtype=f,
        )
        self.accel_per_unit = np.array([d.accel_per_unit_radps2 for d in dyn], dtype=f)
        self.accel_max = np.array([d.accel_max_radps2 for d in dyn], dtype=f)
        self.ref_gain = np.array([d.ref_gain for d in dyn], dtype=f)
        self.ref_phi = np.zeros((n, 3, 4))
        self.ref_gamma = np.zeros((n, 3, 2))
        for i, (d, r) in enumerate(zip(dyn, rates, strict=True)):
            for k in range(3):
                phi, gamma = second_order_step(d.ref_wn_radps[k], d.ref_zeta[k], 1.0 / r)
                self.ref_phi[i, k] = phi
                self.ref_gamma[i, k] = gamma
        self.angle_p = np.array([d.angle_p for d in dyn], dtype=f)
        self.track_gains = np.array([(d.track_p, d.track_i) for d in dyn], dtype=f)
        self.ref_delay = np.array([d.ref_delay_periods for d in dyn], dtype=np.int64)
        if self.ref_delay.min() < 0 or self.ref_delay.max() >= REF_DELAY_MAX:
            raise ValueError(f"ref_delay_periods must be 0..{REF_DELAY_MAX - 1}, got "
                             f"{self.ref_delay.tolist()}")
        self.attitude_error_std = np.array([se.attitude_error_std_rad for se in sen], dtype=f)
        self.attitude_error_phi = np.exp(
            -1.0 / (rates[:, None] * np.array([se.attitude_error_tau_s for se in sen], dtype=f))
        )
        # the heading error's size after each takeoff (Sensors.heading_*): schedule_heading sets
        # attitude_error_std[:, 2] from heading_std_rad, the size it scales
        self.heading_std_rad = self.attitude_error_std[:, 2].copy()
        self.heading_schedule = np.array(
            [(se.heading_takeoff_factor, se.heading_takeoff_s, se.heading_settle_s,
              se.heading_floor_rad) for se in sen], dtype=f).reshape(n, 4)
        self.heading_scheduled = self.sensor_model & (self.heading_schedule[:, 1] > 0.0)
        self.airborne_since_s = np.full(n, np.nan)  # NaN: on the ground
        self._heading_any = bool(self.heading_scheduled.any())
        self._heading_next_s = -math.inf
        order = np.array([se.attitude_error_order for se in sen], dtype=np.int64).reshape(n, 3)
        if not np.isin(order, (1, 2)).all():
            raise ValueError(f"attitude_error_order must be 1 or 2 per axis, got {order.tolist()}")
        self.attitude_error_smooth = np.where(
            order == 2, np.vectorize(sn.smooth_gain)(self.attitude_error_phi), 0.0)
        # complementary-filter estimate error: factor per period, -1 where the axis is off
        tau_g = np.array([se.gyro_integration_tau_s for se in sen], dtype=f).reshape(n, 3)
        self.gyro_integration_phi = np.where(
            tau_g > 0.0, np.exp(-1.0 / (rates[:, None] * np.maximum(tau_g, 1e-9))), -1.0)
        self.gyro_bias_std = np.array([se.gyro_bias_std_radps for se in sen], dtype=f)
        self.gyro_bias_phi = np.exp(
            -1.0 / (rates * np.array([se.gyro_bias_tau_s for se in sen], dtype=f)))
        self.disturbance_ar = np.array(
            [[sn.resonator_coefficients(hz, d.disturbance_zeta, 1.0 / r)
              for hz in d.disturbance_resonance_hz] for d, r in zip(dyn, rates, strict=True)],
            dtype=f,
        ).reshape(n, 3, 3)
        self.velocity_error_std = np.array([se.velocity_error_std_mps for se in sen], dtype=f)
        self.velocity_error_phi = np.exp(
            -1.0 / (rates * np.array([se.velocity_error_tau_s for se in sen]))
        )
        self.velocity_drift_std = np.array([se.velocity_drift_std_mps for se in sen], dtype=f)
        self.velocity_drift_phi = np.exp(
            -1.0 / (rates * np.array([se.velocity_drift_tau_s for se in sen]))
        )
        self.position_error_phi = np.exp(
            -1.0 / (rates * np.array([se.position_error_tau_s for se in sen]))
        )
        self.position_error_share = np.array(
            [se.velocity_error_in_position for se in sen], dtype=f)
        self.hold_wander_std = np.array([se.hold_wander_std_m for se in sen], dtype=f)
        self.hold_wander_ar = np.array(
            [sn.resonator_coefficients(se.hold_wander_hz, se.hold_wander_zeta, 1.0 / r)
             if any(se.hold_wander_std_m) else (0.0, 0.0, 0.0)
             for se, r in zip(sen, rates, strict=True)], dtype=f)
        # states
        self.noise_rng = np.array([sn.noise_seed(0, int(v)) for v in plant.sysid], dtype=np.uint64)
        self.gyro_filter_state = np.zeros((n, 3, 2))
        self.dterm_filter_state = np.zeros((n, 3, 2))
        self.accel_filter_state = np.zeros((n, 3, 2))
        self.gyro_raw = plant.omega_flu_radps.copy()
        self.accel_raw = plant.specific_force_flu_mps2.copy()
        for i in range(n):
            for k in range(3):
                sn.biquad_prime(self.accel_coef[i], self.accel_filter_state[i, k],
                                self.accel_raw[i, k])
        self.rate_meas_flu_radps = np.zeros((n, 3))  # the filtered gyro (ATTITUDE rates)
        self.dgyro = np.zeros((n, 3))
        self.gyro_imu_flu_radps = np.zeros((n, 3))  # HIGHRES_IMU
        self.accel_imu_flu_mps2 = self.accel_raw.copy()
        self.yaw_torque_lpf = np.zeros(n)
        self.shaped_rate = np.zeros((n, 3))
        self.reference = np.zeros((n, 3, 2))
        self.angle_error = np.zeros((n, 3))
        self.track_integral = np.zeros((n, 3))
        # per torque axis, whether the mixer delivered less (+1) or more (-1) than asked at the
        # last physics step (physics.rotors_from_wrench_into): the rate loops stop winding up
        self.torque_limited = np.zeros((n, 3))
        self.torque_next_nm = np.zeros((n, 3))
        self.thrust_next_norm = np.zeros(n)
        self._torque_new = np.zeros((n, 3))
        self.rotation_est = plant.rotation.copy()
        self.position_est_enu_m = plant.position_enu_m.copy()
        self.velocity_est_enu_mps = plant.velocity_enu_mps.copy()
        self._position_prev = plant.position_enu_m.copy()
        self._velocity_prev = plant.velocity_enu_mps.copy()
        self._delay_buffer = np.zeros((n, 3, REF_DELAY_MAX))
        self._delay_index = np.zeros(n, dtype=np.int64)
        self.attitude_error = np.zeros((n, 3))
        self.attitude_error_stage = np.zeros((n, 3))
        self.integration_error = np.zeros((n, 3))
        self.gyro_bias = np.zeros((n, 3))
        self.disturbance_state = np.zeros((n, 3, 3))
        self.hold_wander_state = np.zeros((n, 3, 3))
        #: the hold wander now (ENU [m]) and the setpoint the position loop chases with it
        self.hold_wander_enu_m = np.zeros((n, 3))
        self._wandered_sp = np.zeros((n, 3))
        self.velocity_error = np.zeros((n, 3))
        self.velocity_error_parts = np.zeros((n, 2, 3))  # fast, drift
        self.position_error = np.zeros((n, 3))
        self.attitude_sample_step = np.zeros(n, dtype=np.int64)
        self.position_sample_step = np.zeros(n, dtype=np.int64)
        self._position_prev_step = np.zeros(n, dtype=np.int64)

    def schedule_heading(self, now_s: float, on_ground: np.ndarray) -> None:
        """The heading error's size now (Sensors.heading_*), for the vehicles that schedule it:
        the time since each left the ground picks it (kept here, restarted by each takeoff)."""
        if not self._heading_any or now_s < self._heading_next_s:
            return
        self._heading_next_s = now_s + HEADING_UPDATE_S
        since = self.airborne_since_s
        since[on_ground] = np.nan
        since[~on_ground & np.isnan(since)] = now_s
        airborne_s = now_s - since
        factor, takeoff_s, settle_s, floor = self.heading_schedule.T
        with np.errstate(invalid="ignore"):
            settling = floor + (self.heading_std_rad - floor) * np.exp(
                -np.maximum(airborne_s - takeoff_s, 0.0) / settle_s)
            std = np.where(airborne_s < takeoff_s, factor * self.heading_std_rad, settling)
        std = np.where(np.isnan(airborne_s), floor, std)
        self.attitude_error_std[:, 2] = np.where(self.heading_scheduled, std,
                                                 self.attitude_error_std[:, 2])

    def set_noise(self, i: int, on: bool) -> bool:
        """EMU_NOISE for vehicle i: the sensor model's noise (calibrated personalities); returns
        whether telemetry should add its own white noise instead (the nominal model)."""
        if self.sensor_model[i]:
            self.noise_on[i] = on
            return False
        return on

    def seed_noise(self, i: int, seed: int) -> None:
        """EMU_SEED for vehicle i: restart its sensor-noise stream from (seed, sysid)."""
        self.noise_rng[i] = sn.noise_seed(seed, int(self.sysid[i]))

    def params(self) -> OnboardParams:
        """The parameter arrays, as onboard_step (and the fleet kernel) takes them (built once:
        the arrays are only ever changed in place)."""
        if self._params is None:
            self._params = self._param_tuple()
        return self._params

    def states(self) -> OnboardStates:
        """The state arrays, as onboard_step takes them (built once, like params)."""
        if self._states is None:
            self._states = self._state_tuple()
        return self._states

    def plain(self) -> tuple[tuple, tuple]:
        """params() and states() as plain nested tuples, for the fleet kernel's call (built
        once): numba types a plain tuple of arrays in C but a named one in Python, which for
        these 85 arrays cost some 16 us a call; the kernel names them again (`named_params`,
        `named_states`) at no cost."""
        if self._plain is None:
            self._plain = (_plain(self.params()), _plain(self.states()))
        return self._plain

    def _param_tuple(self) -> OnboardParams:
        return OnboardParams(
            self.rate_loop,
            self.angular_damping_per_s,
            self.drag_decay,
            self.linear_drag_per_s,
            self.thrust_scale,
            self.control_div,
            ImuModel(self.noise_on, self.gyro_noise_std, self.accel_noise_std, self.off_noise_std,
                     self.gyro_coef, self.dterm_coef, self.accel_coef, self.imu_mode),
            self.position_delay,
            self.output_delay,
            Px4RateGains(self.rate_gain_p, self.rate_gain_i, self.rate_gain_d,
                         self.rate_int_limit, self.yaw_alpha, self.accel_per_unit),
            ReferenceGains(self.accel_max, self.ref_gain, self.ref_phi, self.ref_gamma,
                           self.angle_p, self.track_gains, self.ref_delay),
            EstimateNoise(self.attitude_error_std, self.attitude_error_phi,
                          self.attitude_error_smooth, self.velocity_error_std,
                          self.velocity_error_phi, self.velocity_drift_std,
                          self.velocity_drift_phi, self.position_error_phi,
                          self.position_error_share),
            self.disturbance_std,
            self.gyro_integration_phi,
            self.gyro_bias_std,
            self.gyro_bias_phi,
            self.disturbance_ar,
            self.hold_wander_std,
            self.hold_wander_ar,
        )

    def _state_tuple(self) -> OnboardStates:
        return OnboardStates(
            self.noise_rng,
            ImuState(self.gyro_filter_state, self.dterm_filter_state, self.accel_filter_state,
                     self.gyro_raw, self.accel_raw, self.rate_meas_flu_radps, self.dgyro,
                     self.gyro_imu_flu_radps, self.accel_imu_flu_mps2),
            # torque_limited: the fleet kernel's mixer writes it (plant.py)
            RateOutputs(self._torque_new, self.yaw_torque_lpf, self.torque_limited,
                        self.torque_next_nm, self.thrust_next_norm),
            ReferenceState(self.shaped_rate, self.reference, self.angle_error,
                           self.track_integral, self._delay_buffer, self._delay_index),
            self.rotation_est,
            self.position_est_enu_m,
            self.velocity_est_enu_mps,
            self._position_prev,
            self._velocity_prev,
            self.attitude_sample_step,
            self.position_sample_step,
            self._position_prev_step,
            EstimateErrors(self.attitude_error_stage, self.attitude_error,
                           self.velocity_error_parts, self.velocity_error, self.position_error),
            self.integration_error,
            self.gyro_bias,
            self.disturbance_state,
            self.hold_wander_state,
            self.hold_wander_enu_m,
            self._wandered_sp,
        )


def _plain(bundle: tuple) -> tuple:
    """A (nested) named tuple as plain tuples, field for field."""
    return tuple(_plain(v) if isinstance(v, tuple) else v for v in bundle)


@njit(cache=True)
def named_params(t):
    """`OnboardParams` of Onboard.plain()'s parameter tuple."""
    return OnboardParams(t[0], t[1], t[2], t[3], t[4], t[5], ImuModel(*t[6]), t[7], t[8],
                         Px4RateGains(*t[9]), ReferenceGains(*t[10]), EstimateNoise(*t[11]),
                         t[12], t[13], t[14], t[15], t[16], t[17], t[18])


@njit(cache=True)
def named_states(t):
    """`OnboardStates` of Onboard.plain()'s state tuple."""
    return OnboardStates(t[0], ImuState(*t[1]), RateOutputs(*t[2]), ReferenceState(*t[3]), t[4],
                         t[5], t[6], t[7], t[8], t[9], t[10], t[11], EstimateErrors(*t[12]),
                         t[13], t[14], t[15], t[16], t[17], t[18])


@njit(cache=True)
def _with_position_sp(cmd, pos_sp):
    """``cmd`` (`Commands`) with the position setpoints ``pos_sp`` (the hold wander's)."""
    return Commands(cmd.mode, cmd.thrust_cmd, cmd.rate_cmd, cmd.att_cmd, cmd.yaw_rate_ff,
                    cmd.torque_cmd, pos_sp, cmd.vel_ff, cmd.pos_mask, cmd.yaw_sp, cmd.hover)


@njit(cache=True)
def onboard_step(step, dt, cmd, loops, body, on_ground, inertia, tmax, sf_body, cal_par, cal_st):
    """Physics step ``step`` of every calibrated vehicle (rate loop not nominal) whose control
    period it starts (``step % ctrl_div[i] == 0``; in between, thrust_sp and torque_sp hold): an
    IMU sample, the latched estimates, the cascade and the personality's rate loop. One call per
    physics step for the whole fleet (the fleet kernel's), so the parameter and state tuples
    are unpacked once per step, not per vehicle. ``cmd``, ``loops``, ``body``: the fleet's
    `Commands`, `LoopState` and `Body`; ``cal_par``, ``cal_st``: `OnboardParams` and
    `OnboardStates` (fleet_arrays.py)."""
    (mode, thrust_cmd, rate_cmd, att_cmd, yaw_rate_ff, torque_cmd, pos_sp, vel_ff, pos_mask,
     yaw_sp, hover) = cmd
    att_sp, rate_sp, thrust_sp, torque_sp, rate_int, _omega_prev, vel_int = loops
    pos, vel, rot, omega = body
    (loop, _damping, _decay, _drag, _scale, ctrl_div, imu_model, pos_delay, out_delay, px4,
     ref_gains, est_noise, disturbance, integ_phi, bias_std, bias_phi, dist_ar, wander_std,
     wander_ar) = cal_par
    (rng, imu, rate_out, ref_state, rot_est, pos_est, vel_est, pos_prev, vel_prev, att_step,
     pos_step, pos_prev_step, errors, integ_err, gyro_bias, dist_state, wander_state, wander,
     wandered_sp) = cal_st
    noise_on = imu_model.noise_on
    gyro_raw, gyro_imu = imu.gyro_raw_radps, imu.gyro_imu_radps
    torque_new, yaw_lpf, _limited, torque_next, thrust_next = rate_out
    shaped, ref, angle_err, track_int, _delay_buf, _delay_idx = ref_state
    att_err, vel_err, pos_err = errors.attitude_rad, errors.velocity_mps, errors.position_m
    estimated = Body(pos_est, vel_est, rot_est, omega)  # what the cascade flies on
    wandered = _with_position_sp(cmd, wandered_sp)
    for i in range(loop.shape[0]):
        if loop[i] == 0 or step % ctrl_div[i] != 0:
            continue
        m = mode[i]
        landed = on_ground[i]
        dt_c = ctrl_div[i] * dt
        sn.sample_sensors(i, dt_c, m != 0, omega, sf_body, imu_model, rng, imu)
        # estimates as the autopilot reports them (truth plus the estimate errors), with their
        # sample steps; LOCAL_POSITION_NED optionally one period older
        sn.estimate_errors(i, dt_c, noise_on, est_noise, rng, errors)
        sn.gyro_integration_errors(i, dt_c, noise_on, integ_phi, gyro_raw, omega, integ_err)
        sn.gyro_bias_step(i, noise_on, bias_std, bias_phi, rng, gyro_bias, gyro_imu)
        e0 = att_err[i, 0] + integ_err[i, 0]
        e1 = att_err[i, 1] + integ_err[i, 1]
        e2 = att_err[i, 2] + integ_err[i, 2]
        if e0 == 0.0 and e1 == 0.0 and e2 == 0.0:
            for a in range(3):
                for b in range(3):
                    rot_est[i, a, b] = rot[i, a, b]
        else:
            sn.rotate_body(rot[i], e0, e1, e2, rot_est[i])
        att_step[i] = step
        if pos_delay[i] > 0:
            pos_step[i] = pos_prev_step[i]
            pos_prev_step[i] = step
            for k in range(3):
                pos_est[i, k], pos_prev[i, k] = pos_prev[i, k] + pos_err[i, k], pos[i, k]
                vel_est[i, k], vel_prev[i, k] = vel_prev[i, k] + vel_err[i, k], vel[i, k]
        else:
            pos_step[i] = step
            for k in range(3):
                pos_est[i, k] = pos[i, k] + pos_err[i, k]
                vel_est[i, k] = vel[i, k] + vel_err[i, k]
        if m == 0 or m == 1:
            thrust_sp[i] = 0.0 if m == 0 else 0.05
            thrust_next[i] = thrust_sp[i]
            yaw_lpf[i] = 0.0
            for k in range(3):
                torque_sp[i, k] = 0.0
                torque_next[i, k] = 0.0
                rate_int[i, k] = 0.0
                vel_int[i, k] = 0.0
                rate_sp[i, k] = 0.0
                shaped[i, k] = 0.0
                ref[i, k, 0] = 0.0
                ref[i, k, 1] = 0.0
                angle_err[i, k] = 0.0
                track_int[i, k] = 0.0
            continue
        if m == 4:
            thrust_sp[i] = thrust_cmd[i]
            for k in range(3):
                torque_sp[i, k] = torque_cmd[i, k] * tmax[i, k]
            continue
        if m == 5:  # the autopilot's own position loop flies on its estimates, as PX4's does
            sp = cmd
            if noise_on[i] and not landed and wander_ar[i, 2] != 0.0:
                sp = wandered
                sn.hold_wander(i, rng, wander_std, wander_ar, wander_state, wander, pos_sp,
                               wandered_sp)
            thr = position_control(i, estimated, sp, loops, landed, dt_c)
            attitude_control(i, rot_est, att_sp, yaw_rate_ff, rate_sp)
        elif m == 3:
            thr = thrust_cmd[i]
            att_sp[i] = att_cmd[i]
            attitude_control(i, rot_est, att_sp, yaw_rate_ff, rate_sp)
        else:  # m == 2
            thr = thrust_cmd[i]
            for k in range(3):
                rate_sp[i, k] = rate_cmd[i, k]
        if loop[i] == 1:
            px4_rate_control(i, loops, imu, px4, inertia, rate_out, landed, dt_c)
        else:
            reference_rate_control(i, loops, imu, body, ref_gains, ref_state, inertia,
                                   rate_out, landed, dt_c)
        if noise_on[i] and m != 0 and (disturbance[i, 0] != 0.0 or disturbance[i, 1] != 0.0
                                       or disturbance[i, 2] != 0.0):  # process noise
            d0, d1 = sn.gauss_pair(rng, i)
            d2, _ = sn.gauss_pair(rng, i)
            dist = (d0, d1, d2)
            for k in range(3):
                d = sn.resonator_step(dist_ar[i, k], dist_state[i, k], dist[k])
                torque_new[i, k] += inertia[i, k] * disturbance[i, k] * d
        if out_delay[i] > 0:  # what the motors get now was computed one period ago
            thrust_sp[i] = thrust_next[i]
            thrust_next[i] = thr
            for k in range(3):
                torque_sp[i, k] = torque_next[i, k]
                torque_next[i, k] = torque_new[i, k]
        else:
            thrust_sp[i] = thr
            for k in range(3):
                torque_sp[i, k] = torque_new[i, k]
