"""The telemetry errors of an autopilot's estimator, as `gcs sim` puts them on what the law reads.

With `sim.autopilot` set and `sim.telemetry_noise` true, the law's inputs at each tick carry the
errors the bundled emulator's personality of that autopilot reports (vehicle_emulator/config/
personality.py's Sensors, fitted on the SITL recordings; the equations of its estimate_errors):

* velocity: the sum of two first-order Gauss-Markov processes per axis (north, east, up), a fast
  one and a slow drift;
* position: the share of that velocity error the estimator integrates, forgotten over its own
  time constant (PX4 SIH's reported position integrates none of it; ArduCopter's EKF3 all, over
  3 s: its position and velocity estimates agree, so gcs fly's correction toward the position's
  rate cannot remove the error, and the law flies the reported position);
* attitude: per body axis a first-order process of the gyro noise integrated and forgotten
  (the complementary filter's tilt: 1 sigma = sigma_sample sqrt(T_sample tau / 2)), plus the
  estimator's own slow error, first or second order (two equal poles);
* body rates: white noise of the rates the autopilot streams, its raw gyro samples through its
  second-order low pass (1 sigma = sigma_sample sqrt(2 B T_sample), B = 1.11 f_c, the filter's
  noise bandwidth);
* acceleration: as gcs fly computes it from HIGHRES_IMU (gcs/fly/telemetry.py), the specific
  force the accelerometer reports (body FLU, with its white noise: PX4 the mean of two raw
  samples, ArduCopter its low-passed one) turned to the world by the REPORTED attitude, minus
  g e3. So an attitude error e of the estimate reads as a horizontal acceleration of about g e
  that the vehicle does not have, and the law's u' (derivatives.force_derivatives) acts on it.

The law then reads the velocity as gcs fly's does (gcs/fly/consistent.py): the reported velocity
plus the low-passed difference between the reported position's rate and it
(fly.velocity_from_position_s).

The log records the positions as gcs fly records them: each vehicle's latest LOCAL_POSITION_NED,
the reported one, which at some ticks is still the previous stream period's (`held_share` of the
vehicles and ticks, from a draw of its own): the team's samples do not all arrive before every
tick, so a pair's error carries the distance one vehicle flew in a stream period. The law does
not see it: with fly.predict gcs fly carries each sample to when its setpoint acts.

Not modelled here: the position-hold wander (the law does not fly the autopilot's hold), the
emulator's angular disturbances and IMU details. The random numbers come from the run's seed.
"""

from __future__ import annotations

import math
from statistics import NormalDist
from typing import NamedTuple

import numpy as np
from numba import njit

from gcs.control.consistency import (
    ACCELERATION_JUMP_MPS2,
    ACCELERATION_MAX_MPS2,
    VELOCITY_JUMP_MPS,
    VELOCITY_MAX_MPS,
)

#: Processes per vehicle and tick: 3 gyro, 3 integrated-gyro tilt, 3 slow attitude, 3 fast
#: velocity, 3 velocity drift, 3 accelerometer.
DRAWS = 18
#: Process states per vehicle (SimNoise.state)
STATES = 18
#: gcs fly asks LOCAL_POSITION_NED at min(tick rate, this) (docs/gcs.md, PREFLIGHT)
POSITION_STREAM_MAX_HZ = 100.0


class NoiseModel(NamedTuple):
    """Sizes (1 sigma) and time constants [s] of one autopilot's telemetry errors."""

    gyro_std_radps: tuple[float, float, float]  # body FLU, per tick
    tilt_std_rad: tuple[float, float, float]  # integrated gyro noise, roll / pitch / yaw
    tilt_tau_s: float
    attitude_std_rad: tuple[float, float, float]  # the estimator's slow error, roll/pitch/yaw
    attitude_tau_s: tuple[float, float, float]
    attitude_order: tuple[int, int, int]
    velocity_std_mps: tuple[float, float, float]  # north, east, up
    velocity_tau_s: float
    drift_std_mps: tuple[float, float, float]
    drift_tau_s: float
    accel_std_mps2: tuple[float, float, float]  # body FLU, per tick: HIGHRES_IMU's
    # the share of the velocity error the reported position integrates, and its decay [s]
    position_share: float = 0.0
    position_tau_s: float = 1.0
    # the share of (vehicle, tick) pairs whose recorded position is still the previous stream
    # period's (0: none; with it each vehicle takes one more draw per tick)
    held_share: float = 0.0


def _filtered(sample_std: float, sample_s: float, cutoff_hz: float) -> float:
    """1 sigma of white samples through a second-order Butterworth low pass at cutoff_hz."""
    return sample_std * math.sqrt(2.0 * 1.11 * cutoff_hz * sample_s)


def _integrated(sample_std: float, sample_s: float, tau_s: float) -> float:
    """1 sigma of white samples integrated and forgotten over tau_s (a leaky integrator)."""
    return sample_std * math.sqrt(sample_s * tau_s / 2.0)


#: PX4 v1.16 SIH (the px4 personality's PX4_SENSORS): gyro 0.14 / 0.07 / 0.03 rad/s per 4 ms
#: sample through IMU_GYRO_CUTOFF 40 Hz; tilt integrated over 6 s on roll and pitch; EKF2's slow
#: pitch (0.016 rad) and heading (0.058 rad, second order; stationary: the personality sizes its
#: heading error by the time since takeoff, docs/sweep.md) errors over 4 s; velocity 0.126 /
#: 0.126 / 0.10 m/s over 1.5 s plus a 0.10 m/s drift over 10 s; accelerometer 0.5 / 1.7 / 1.4
#: m/s^2 per 4 ms sample, HIGHRES_IMU the mean of two.
PX4_NOISE = NoiseModel(
    gyro_std_radps=tuple(_filtered(s, 0.004, 40.0) for s in (0.14, 0.07, 0.03)),
    tilt_std_rad=(_integrated(0.14, 0.004, 6.0), _integrated(0.07, 0.004, 6.0), 0.0),
    tilt_tau_s=6.0,
    attitude_std_rad=(0.0, 0.016, 0.058), attitude_tau_s=(4.0, 4.0, 4.0),
    attitude_order=(1, 1, 2),
    velocity_std_mps=(0.126, 0.126, 0.10), velocity_tau_s=1.5,
    drift_std_mps=(0.10, 0.10, 0.10), drift_tau_s=10.0,
    accel_std_mps2=tuple(s / math.sqrt(2.0) for s in (0.5, 1.7, 1.4)),
)
#: ArduCopter 4.7.0-dev SITL (ARDUPILOT_SENSORS): no gyro noise; EKF3's velocity 3-5 mm/s over
#: 5 s, which its position integrates and forgets over 3 s (5-12 mm); attitude errors of tens of
#: microradians; the accelerometer's 10 / 12 / 0.7 mm/s^2 per 2 ms sample (its 400 Hz loop on
#: whole physics steps) through INS_ACCEL_FILTER 20 Hz. Held samples: 8 % of the records, the
#: mean over the four vehicles of the share of gcs fly's ticks at which a vehicle's latest
#: LOCAL_POSITION_NED was a period older than the newest of the team's (0, 6, 11, 16 %, the
#: personality's fleet sending the four in team order; tlog of its flight, seed 1).
ARDUPILOT_NOISE = NoiseModel(
    gyro_std_radps=(0.0, 0.0, 0.0), tilt_std_rad=(0.0, 0.0, 0.0), tilt_tau_s=1.0,
    attitude_std_rad=(3.0e-5, 3.2e-5, 4.5e-5), attitude_tau_s=(0.15, 0.15, 3.0),
    attitude_order=(1, 1, 1),
    velocity_std_mps=(0.0032, 0.0052, 0.002), velocity_tau_s=5.0,
    drift_std_mps=(0.0, 0.0, 0.0), drift_tau_s=1.0,
    accel_std_mps2=tuple(_filtered(s, 0.002, 20.0) for s in (0.0102, 0.0116, 0.0007)),
    position_share=1.0, position_tau_s=3.0,
    held_share=0.08,
)
NOISE_MODELS = {"px4": PX4_NOISE, "ardupilot": ARDUPILOT_NOISE}


class SimNoise(NamedTuple):
    """The kernel's view: sizes, factors per tick, the draws and the processes' states."""

    active: bool
    gyro_std: np.ndarray  # (3,)
    tilt_std: np.ndarray  # (3,)
    tilt_phi: float
    att_std: np.ndarray  # (3,)
    att_phi: np.ndarray  # (3,)
    att_second: np.ndarray  # (3,) bool: two equal poles
    vel_std: np.ndarray  # (3,) ENU
    vel_phi: float
    drift_std: np.ndarray  # (3,) ENU
    drift_phi: float
    accel_std: np.ndarray  # (3,) body FLU
    pos_share: float  # the share of the velocity error the position integrates
    pos_phi: float
    held_threshold: float  # a recorded position is held when draw DRAWS is below (-inf: never)
    held_period_s: float  # the position stream's period
    draws: np.ndarray  # (ticks, n, DRAWS or DRAWS + 1) standard normals
    # (n, 18): tilt 0-2, attitude 3-5, its first stage 6-8, vel 9-11, drift 12-14, position 15-17
    state: np.ndarray
    # gcs fly's velocity consistency (gcs/fly/consistent.py): v_law = v + c, c the low-passed
    # p' - v; consistency_s 0: the reported velocity as it is
    consistency_s: float
    consistency: np.ndarray  # (n, 3) c
    last: np.ndarray  # (n, 6): the previous tick's reported p and v (NaN before the first)
    # and its acceleration's (fly.acceleration_from_velocity_s): a_law = a + c_a, c_a the
    # low-passed v_law' - a; 0: the acceleration as the accelerometer gives it
    accel_consistency_s: float
    accel_consistency: np.ndarray  # (n, 3) c_a
    accel_last: np.ndarray  # (n, 6): the previous tick's v_law and a (NaN before the first)


def make_noise(model: NoiseModel | None, ticks: int, n: int, tick_s: float,
               draws: np.ndarray | None = None, consistency_s: float = 0.0,
               accel_consistency_s: float = 0.0) -> SimNoise:
    """The noise of n vehicles over `ticks` ticks (`draws` (ticks, n, DRAWS): the run's normals;
    None with model None: inactive); `consistency_s`: fly.velocity_from_position_s,
    `accel_consistency_s`: fly.acceleration_from_velocity_s."""
    extra = (consistency_s, np.zeros((n, 3)), np.full((n, 6), np.nan),
             accel_consistency_s, np.zeros((n, 3)), np.full((n, 6), np.nan))
    if model is None:
        zero = np.zeros(3)
        return SimNoise(False, zero, zero, 0.0, zero, zero, np.zeros(3, dtype=np.bool_), zero,
                        0.0, zero, 0.0, zero, 0.0, 0.0, -math.inf, 0.0, np.zeros((1, n, DRAWS)),
                        np.zeros((n, STATES)), *extra)
    neu_to_enu = [1, 0, 2]
    return SimNoise(
        True, np.array(model.gyro_std_radps), np.array(model.tilt_std_rad),
        math.exp(-tick_s / model.tilt_tau_s), np.array(model.attitude_std_rad),
        np.exp(-tick_s / np.array(model.attitude_tau_s)),
        np.array([o == 2 for o in model.attitude_order]),
        np.array(model.velocity_std_mps)[neu_to_enu], math.exp(-tick_s / model.velocity_tau_s),
        np.array(model.drift_std_mps)[neu_to_enu], math.exp(-tick_s / model.drift_tau_s),
        np.array(model.accel_std_mps2), model.position_share,
        math.exp(-tick_s / model.position_tau_s),
        NormalDist().inv_cdf(model.held_share) if model.held_share > 0.0 else -math.inf,
        max(tick_s, 1.0 / POSITION_STREAM_MAX_HZ), np.ascontiguousarray(draws),
        np.zeros((n, STATES)), *extra)


def noise_draws(seed: int, ticks: int, n: int, model: NoiseModel | None = None) -> np.ndarray:
    """The run's standard normals (a stream of its own beside the link's losses): DRAWS per
    vehicle and tick, one more when `model` holds recorded positions."""
    count = DRAWS + (1 if model is not None and model.held_share > 0.0 else 0)
    return np.random.default_rng([seed, 1]).standard_normal((ticks, n, count))


@njit(cache=True)
def _complementary(time_constant_s, c, last, x, rate, tick_s, max_c, jump_at, out):
    """gcs fly's consistency filter (gcs/fly/consistent.py) for one vehicle: out = rate + c, c
    the rate of x minus `rate` (trapezoid between ticks) low-passed over time_constant_s; `last`
    (6,) holds the previous tick's x and rate."""
    if time_constant_s > 0.0 and not math.isnan(last[0]):
        alpha = 1.0 - math.exp(-tick_s / time_constant_s)
        jump = False
        diff = np.empty(3)
        for k in range(3):
            diff[k] = (x[k] - last[k]) / tick_s - 0.5 * (rate[k] + last[3 + k])
            jump = jump or abs(diff[k]) > jump_at
        if not jump:
            for k in range(3):
                c[k] = min(max(c[k] + alpha * (diff[k] - c[k]), -max_c), max_c)
    for k in range(3):
        last[k] = x[k]
        last[3 + k] = rate[k]
        out[k] = rate[k] + c[k]


@njit(cache=True)
def add_telemetry_errors(noise, tick, p, v, rot, w, acc, g, tick_s):
    """Advance the processes by one tick and return copies of p, v, R, w, a with the errors on (v as
    gcs fly's law reads it: with its consistency correction; a, the world acceleration, as gcs
    fly computes it: the accelerometer's specific force R^T (a + g e3) plus its noise, turned by
    the reported R, minus g e3, with its own consistency correction toward v's rate)."""
    n = v.shape[0]
    p_out, v_out, rot_out, w_out, acc_out = p.copy(), v.copy(), rot.copy(), w.copy(), acc.copy()
    s = noise.state
    # each process's drive per tick: sqrt(1 - phi^2) of its stationary 1 sigma
    kt = math.sqrt(1.0 - noise.tilt_phi * noise.tilt_phi)
    kv = math.sqrt(1.0 - noise.vel_phi * noise.vel_phi)
    kd = math.sqrt(1.0 - noise.drift_phi * noise.drift_phi)
    for i in range(n):
        d = noise.draws[tick, i]
        e = np.empty(3)
        for k in range(3):
            s[i, k] = noise.tilt_phi * s[i, k] + kt * noise.tilt_std[k] * d[3 + k]
            pa = noise.att_phi[k]
            ka = math.sqrt(1.0 - pa * pa)
            if noise.att_second[k]:
                # two equal poles: a unit stage low-passed once more with the gain that makes
                # the output's stationary 1 sigma att_std ((1 - pa^2) / sqrt(1 + pa^2) of it)
                s[i, 6 + k] = pa * s[i, 6 + k] + ka * d[6 + k]
                gain = noise.att_std[k] * (1.0 - pa * pa) / math.sqrt(1.0 + pa * pa)
                s[i, 3 + k] = pa * s[i, 3 + k] + gain * s[i, 6 + k]
            else:
                s[i, 3 + k] = pa * s[i, 3 + k] + ka * noise.att_std[k] * d[6 + k]
            s[i, 9 + k] = noise.vel_phi * s[i, 9 + k] + kv * noise.vel_std[k] * d[9 + k]
            s[i, 12 + k] = noise.drift_phi * s[i, 12 + k] + kd * noise.drift_std[k] * d[12 + k]
            s[i, 15 + k] = (noise.pos_phi * s[i, 15 + k]
                            + noise.pos_share * (s[i, 9 + k] + s[i, 12 + k]) * tick_s)
            p_out[i, k] += s[i, 15 + k]
            v_out[i, k] += s[i, 9 + k] + s[i, 12 + k]
            w_out[i, k] += noise.gyro_std[k] * d[k]
            e[k] = s[i, k] + s[i, 3 + k]
        # the reported attitude: the true one turned by the body-axis error e (Rodrigues)
        angle = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        if angle > 0.0:
            kx = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
            turn = (np.eye(3) + (math.sin(angle) / angle) * kx
                    + ((1.0 - math.cos(angle)) / (angle * angle)) * (kx @ kx))
            rot_out[i] = rot[i] @ turn
        _reported_acceleration(noise, d, rot[i], rot_out[i], acc[i], g, acc_out[i])
        _complementary(noise.consistency_s, noise.consistency[i], noise.last[i], p_out[i],
                       v_out[i].copy(), tick_s, VELOCITY_MAX_MPS, VELOCITY_JUMP_MPS,
                       v_out[i])
        _complementary(noise.accel_consistency_s, noise.accel_consistency[i],
                       noise.accel_last[i], v_out[i], acc_out[i].copy(), tick_s,
                       ACCELERATION_MAX_MPS2, ACCELERATION_JUMP_MPS2, acc_out[i])
    return p_out, v_out, rot_out, w_out, acc_out


@njit(cache=True)
def _reported_acceleration(noise, d, rot, rot_reported, acc, g, out):
    """One vehicle's world acceleration from its accelerometer as the law reads it: the specific
    force f = R^T (a + g e3) (body FLU) plus the noise of draws d[15:18], turned by the reported
    attitude: R_reported f - g e3."""
    f = np.empty(3)
    for b in range(3):
        f[b] = (rot[0, b] * acc[0] + rot[1, b] * acc[1] + rot[2, b] * (acc[2] + g)
                + noise.accel_std[b] * d[15 + b])
    for k in range(3):
        out[k] = rot_reported[k, 0] * f[0] + rot_reported[k, 1] * f[1] + rot_reported[k, 2] * f[2]
    out[2] -= g


@njit(cache=True)
def recorded_position(noise, tick, p, v):
    """The positions (n, 3) gcs fly records at this tick: each vehicle's latest reported one,
    the truth plus its estimate's error, or, where its draw DRAWS is below held_threshold, the
    previous stream period's (p - v T)."""
    out = p + noise.state[:, 15:18]
    if noise.held_threshold > -math.inf:
        for i in range(p.shape[0]):
            if noise.draws[tick, i, DRAWS] < noise.held_threshold:
                for k in range(3):
                    out[i, k] -= v[i, k] * noise.held_period_s
    return out
