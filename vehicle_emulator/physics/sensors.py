"""Onboard sensor model of the calibrated personalities: seeded IMU noise, filters, estimates.

Per vehicle and control period (personality.Sensors): a raw gyro and accelerometer sample (true
body rate and specific force, FLU, plus white Gaussian noise from a per-vehicle counter-based
generator), the gyro low pass the rate loop flies on, the D-term derivative, HIGHRES_IMU as the
autopilot reports it, and the latched estimates (attitude, position) with their sample times.

The numba kernels work on vehicle ``i`` of batched arrays and are called from plant.py's fleet
kernel; the coefficient helpers are plain Python (run once per vehicle). Pure: no clock, no I/O.
Noise is reproducible: vehicle i's stream depends only on (seed, sysid), not on the fleet.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "PASS_THROUGH",
    "biquad",
    "biquad_coefficients",
    "biquad_prime",
    "gauss_pair",
    "noise_seed",
    "smooth_gain",
    "one_pole_alpha",
]

PASS_THROUGH = (1.0, 0.0, 0.0, 0.0, 0.0)  # b0, b1, b2, a1, a2 of "no filter"
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_TWO_PI = 2.0 * math.pi


def biquad_coefficients(cutoff_hz: float, sample_hz: float) -> tuple[float, ...]:
    """2nd-order Butterworth low pass (b0, b1, b2, a1, a2), bilinear with prewarping: PX4's
    LowPassFilter2p. A cutoff <= 0 or at/above Nyquist gives PASS_THROUGH."""
    if cutoff_hz <= 0.0 or cutoff_hz >= 0.5 * sample_hz:
        return PASS_THROUGH
    ohm = math.tan(math.pi * cutoff_hz / sample_hz)
    q = 2.0 * math.cos(math.pi / 4.0)  # sqrt(2): Butterworth
    c = 1.0 + q * ohm + ohm * ohm
    b0 = ohm * ohm / c
    return (b0, 2.0 * b0, b0, 2.0 * (ohm * ohm - 1.0) / c, (1.0 - q * ohm + ohm * ohm) / c)


def one_pole_alpha(cutoff_hz: float, dt_s: float) -> float:
    """PX4 AlphaFilter gain dt / (dt + 1 / (2 pi f)); 1.0 (no filter) for a cutoff <= 0."""
    if cutoff_hz <= 0.0:
        return 1.0
    return dt_s / (dt_s + 1.0 / (_TWO_PI * cutoff_hz))


def biquad_prime(coef: np.ndarray, state: np.ndarray, value: float) -> None:
    """Set a biquad's state (2,) to its steady state for a constant input ``value``."""
    b0, b1, b2, a1, a2 = coef
    d = value / (1.0 + a1 + a2)
    state[0] = d
    state[1] = d


def smooth_gain(phi: float) -> float:
    """Gain of a Gauss-Markov process's second stage, x2 <- phi x2 + c x1 with x1 a unit-variance
    first-order stage of the same factor ``phi``, that gives x2 unit variance:
    Var x2 = c^2 (1 + phi^2) / (1 - phi^2)^2."""
    return (1.0 - phi * phi) / math.sqrt(1.0 + phi * phi)


def noise_seed(seed: int, sysid: int) -> np.uint64:
    """Initial generator state of one vehicle: a splitmix64 hash of (seed, sysid)."""
    z = (int(seed) * 0x100000001B3 + int(sysid) * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
    for _ in range(2):
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9 & 0xFFFFFFFFFFFFFFFF
        z = (z ^ (z >> 27)) * 0x94D049BB133111EB & 0xFFFFFFFFFFFFFFFF
        z ^= z >> 31
    return np.uint64(z)


@njit(cache=True)
def _uniform(rng: np.ndarray, i: int) -> float:
    """Next uniform in (0, 1] of vehicle i's splitmix64 stream (advances rng[i])."""
    rng[i] += _GOLDEN
    z = rng[i]
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return (float(z >> np.uint64(11)) + 1.0) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def gauss_pair(rng: np.ndarray, i: int) -> tuple[float, float]:
    """Two independent standard normal draws for vehicle i (Box-Muller)."""
    r = math.sqrt(-2.0 * math.log(_uniform(rng, i)))
    a = _TWO_PI * _uniform(rng, i)
    return r * math.cos(a), r * math.sin(a)


@njit(cache=True)
def biquad(coef: np.ndarray, state: np.ndarray, x: float) -> float:
    """One step of a biquad (direct form II, as PX4's LowPassFilter2p); state (2,) updated."""
    d0 = x - state[0] * coef[3] - state[1] * coef[4]
    y = d0 * coef[0] + state[0] * coef[1] + state[1] * coef[2]
    state[1] = state[0]
    state[0] = d0
    return y


@njit(cache=True, inline="always")
def sample_sensors(i, dt_c, motors_on, omega, sf, imu, rng, st):
    """One IMU sample of vehicle i (FLU), time step ``dt_c``, of the true body rate ``omega[i]``
    and specific force ``sf[i]``, with the model ``imu`` (fleet_arrays.ImuModel) into ``st``
    (fleet_arrays.ImuState): the raw samples ``gyro_raw[i]`` and ``accel_raw[i]`` (the previous
    ones on entry), the filtered rate ``rate_meas[i]`` (what the
    rate loop and ATTITUDE see), the filtered derivative ``dgyro[i]`` of the raw gyro (PX4's D
    term), and HIGHRES_IMU's ``gyro_imu[i]``/``accel_imu[i]``:
    ``imu_mode`` 0 the raw sample, 1 the mean of the last two raw samples, 2 the filtered gyro
    and accelerometer. Noise: white, ``gyro_std``/``accel_std`` per axis with the motors on,
    ``off_std`` (gyro, accel) with them off, none when ``noise_on[i]`` is False."""
    noise_on, gyro_std, accel_std, off_std, gyro_coef, dterm_coef, accel_coef, imu_mode = imu
    (gyro_state, dterm_state, accel_state, gyro_raw, accel_raw, rate_meas, dgyro, gyro_imu,
     accel_imu) = st
    ng = (0.0, 0.0, 0.0)
    na = (0.0, 0.0, 0.0)
    std_sum = gyro_std[i, 0] + gyro_std[i, 1] + gyro_std[i, 2] + accel_std[i, 0]
    std_sum += accel_std[i, 1] + accel_std[i, 2] + off_std[i, 0] + off_std[i, 1]
    if noise_on[i] and std_sum > 0.0:
        g0, g1 = gauss_pair(rng, i)
        g2, a0 = gauss_pair(rng, i)
        a1, a2 = gauss_pair(rng, i)
        if motors_on:
            ng = (g0 * gyro_std[i, 0], g1 * gyro_std[i, 1], g2 * gyro_std[i, 2])
            na = (a0 * accel_std[i, 0], a1 * accel_std[i, 1], a2 * accel_std[i, 2])
        else:
            ng = (g0 * off_std[i, 0], g1 * off_std[i, 0], g2 * off_std[i, 0])
            na = (a0 * off_std[i, 1], a1 * off_std[i, 1], a2 * off_std[i, 1])
    mode = imu_mode[i]
    for k in range(3):
        g = omega[i, k] + ng[k]
        a = sf[i, k] + na[k]
        rate_meas[i, k] = biquad(gyro_coef[i], gyro_state[i, k], g)
        dgyro[i, k] = biquad(dterm_coef[i], dterm_state[i, k], (g - gyro_raw[i, k]) / dt_c)
        a_f = biquad(accel_coef[i], accel_state[i, k], a)
        if mode == 0:
            gyro_imu[i, k] = g
            accel_imu[i, k] = a
        elif mode == 1:
            gyro_imu[i, k] = 0.5 * (g + gyro_raw[i, k])
            accel_imu[i, k] = 0.5 * (a + accel_raw[i, k])
        else:
            gyro_imu[i, k] = rate_meas[i, k]
            accel_imu[i, k] = a_f
        gyro_raw[i, k] = g
        accel_raw[i, k] = a


@njit(cache=True, inline="always")
def estimate_errors(i, dt_c, noise_on, noise, rng, errors):
    """Advance vehicle i's estimate errors ``errors`` (fleet_arrays.EstimateErrors: att_stage,
    att_err, vel_parts, vel_err, pos_err) by one control period with the sizes and factors
    ``noise`` (fleet_arrays.EstimateNoise: att_std, att_phi, att_smooth, vel_std, vel_phi,
    drift_std, drift_phi, pos_phi, pos_share): Gauss-Markov attitude errors
    (roll, pitch, yaw; body axes; factors ``att_phi[i, k]`` per axis), first order where
    ``att_smooth[i, k]`` is 0, else second order (two equal poles: a unit first-order stage
    ``att_stage`` low-passed once more with gain ``att_smooth``, smooth at short lags), and
    velocity errors (ENU arrays; ``vel_std[i]`` = (north, east, vertical), LOCAL_POSITION_NED's
    x, y, z), stationary 1 sigma ``*_std``, factors ``*_phi = exp(-dt/tau)``. The velocity
    error ``vel_err`` is the sum of two independent first-order processes kept in ``vel_parts``:
    a fast one (``vel_std``, ``vel_phi``) and a slow drift (``drift_std``, ``drift_phi``; axes as
    ``vel_std``). The position error integrates the share ``pos_share[i]`` of the velocity error
    and decays by ``pos_phi`` per period (share 1: position and velocity estimates agree; 0: the
    reported velocity carries an error the reported position does not show). Off (held at zero)
    without noise."""
    (att_std, att_phi, att_smooth, vel_std, vel_phi, drift_std, drift_phi, pos_phi,
     pos_share) = noise
    att_stage, att_err, vel_parts, vel_err, pos_err = errors
    if not noise_on[i]:
        for k in range(3):
            att_err[i, k] = 0.0
            att_stage[i, k] = 0.0
            vel_err[i, k] = 0.0
            vel_parts[i, 0, k] = 0.0
            vel_parts[i, 1, k] = 0.0
            pos_err[i, k] = 0.0
        return
    pv = vel_phi[i]
    if att_std[i, 0] != 0.0 or att_std[i, 1] != 0.0 or att_std[i, 2] != 0.0:
        n0, n1 = gauss_pair(rng, i)
        n2, _ = gauss_pair(rng, i)
        na = (n0, n1, n2)
        for k in range(3):
            pa = att_phi[i, k]
            ka = math.sqrt(max(0.0, 1.0 - pa * pa))
            if att_smooth[i, k] == 0.0:
                att_err[i, k] = pa * att_err[i, k] + ka * att_std[i, k] * na[k]
            else:
                att_stage[i, k] = pa * att_stage[i, k] + ka * na[k]
                c = att_smooth[i, k] * att_std[i, k]
                att_err[i, k] = pa * att_err[i, k] + c * att_stage[i, k]
    if vel_std[i, 0] != 0.0 or vel_std[i, 1] != 0.0 or vel_std[i, 2] != 0.0:
        _markov_enu(i, pv, vel_std, rng, vel_parts, 0)
    if drift_std[i, 0] != 0.0 or drift_std[i, 1] != 0.0 or drift_std[i, 2] != 0.0:
        _markov_enu(i, drift_phi[i], drift_std, rng, vel_parts, 1)
    for k in range(3):
        vel_err[i, k] = vel_parts[i, 0, k] + vel_parts[i, 1, k]
        pos_err[i, k] = pos_phi[i] * pos_err[i, k] + pos_share[i] * vel_err[i, k] * dt_c


@njit(cache=True)
def _markov_enu(i, phi, std_neu, rng, parts, j):
    """One period of the first-order process ``parts[i, j]`` (ENU) of stationary 1 sigma
    ``std_neu[i]`` given as (north, east, up) and factor ``phi``."""
    kv = math.sqrt(max(0.0, 1.0 - phi * phi))
    n3, n4 = gauss_pair(rng, i)
    n5, _ = gauss_pair(rng, i)
    nv = (n3, n4, n5)
    for k in range(3):
        s = std_neu[i, 1] if k == 0 else (std_neu[i, 0] if k == 1 else std_neu[i, 2])
        parts[i, j, k] = phi * parts[i, j, k] + kv * s * nv[k]


@njit(cache=True)
def hold_wander(i, rng, std, ar, state, wander, pos_sp, out):
    """Advance vehicle i's position-hold wander by one control period (personality.Sensors:
    a unit-variance band-pass resonator per axis, ``ar[i]`` its coefficients, scaled by ``std[i]``
    = (north, east, up)) and write the setpoint its position loop chases, ``pos_sp[i]`` plus the
    wander (ENU), to ``out[i]``."""
    n0, n1 = gauss_pair(rng, i)
    n2, _ = gauss_pair(rng, i)
    noise = (n0, n1, n2)
    for k in range(3):
        s = std[i, 1] if k == 0 else (std[i, 0] if k == 1 else std[i, 2])
        wander[i, k] = s * resonator_step(ar[i], state[i, k], noise[k])
        out[i, k] = pos_sp[i, k] + wander[i, k]


@njit(cache=True)
def rotate_body(r: np.ndarray, e0: float, e1: float, e2: float, out: np.ndarray) -> None:
    """out = r exp(hat(e)) (Rodrigues): r (3, 3) turned by the small body-frame rotation e."""
    th = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if th < 1e-12:
        for a in range(3):
            for b in range(3):
                out[a, b] = r[a, b]
        return
    x, y, z = e0 / th, e1 / th, e2 / th
    s, c = math.sin(th), 1.0 - math.cos(th)
    m = (
        (1.0 - c * (y * y + z * z), -s * z + c * x * y, s * y + c * x * z),
        (s * z + c * x * y, 1.0 - c * (x * x + z * z), -s * x + c * y * z),
        (-s * y + c * x * z, s * x + c * y * z, 1.0 - c * (x * x + y * y)),
    )
    for a in range(3):
        for b in range(3):
            out[a, b] = r[a, 0] * m[0][b] + r[a, 1] * m[1][b] + r[a, 2] * m[2][b]


@njit(cache=True)
def gyro_integration_errors(i, dt_c, noise_on, phi, gyro_raw, omega, err):
    """Advance vehicle i's complementary-filter attitude error by one control period, per body
    axis with ``phi[i, k] = exp(-dt/tau) >= 0`` (negative: axis off, held at zero): the raw
    gyro sample's noise (``gyro_raw - omega``) integrated, decaying as the filter's correction
    pulls the estimate back to the true attitude."""
    for k in range(3):
        if not noise_on[i] or phi[i, k] < 0.0:
            err[i, k] = 0.0
        else:
            err[i, k] = phi[i, k] * err[i, k] + (gyro_raw[i, k] - omega[i, k]) * dt_c


@njit(cache=True)
def gyro_bias_step(i, noise_on, std, phi, rng, bias, gyro_imu):
    """Advance vehicle i's gyro bias (first-order Gauss-Markov, stationary 1 sigma ``std[i]``,
    factor ``phi[i]`` per period) and add it to the HIGHRES_IMU gyro ``gyro_imu[i]``. Off (zero,
    no draws) without noise or with a zero size."""
    if not noise_on[i] or (std[i, 0] == 0.0 and std[i, 1] == 0.0 and std[i, 2] == 0.0):
        for k in range(3):
            bias[i, k] = 0.0
        return
    p = phi[i]
    kb = math.sqrt(max(0.0, 1.0 - p * p))
    n0, n1 = gauss_pair(rng, i)
    n2, _ = gauss_pair(rng, i)
    nb = (n0, n1, n2)
    for k in range(3):
        bias[i, k] = p * bias[i, k] + kb * std[i, k] * nb[k]
        gyro_imu[i, k] += bias[i, k]


def resonator_coefficients(frequency_hz: float, zeta: float, dt_s: float) -> tuple[float, float,
                                                                                    float]:
    """(a1, a2, gain) of the band-pass resonator y_k = a1 y_{k-1} + a2 y_{k-2} + gain (w_k -
    w_{k-1}) driven by unit white noise w: poles at ``frequency_hz`` with damping ``zeta``, a
    zero at DC (a limit cycle carries no steady part), the gain making y's stationary std 1.
    ``frequency_hz`` 0: (0, 0, 1) and y = w (white; resonator_step then skips the zero)."""
    if frequency_hz <= 0.0:
        return (0.0, 0.0, 1.0)
    if not 0.0 < zeta < 1.0:
        raise ValueError(f"disturbance_zeta: expected 0 < zeta < 1, got {zeta}")
    w = 2.0 * math.pi * frequency_hz
    if w * dt_s >= math.pi:
        raise ValueError(f"disturbance_resonance_hz: {frequency_hz} Hz is above the control "
                         f"loop's Nyquist frequency {0.5 / dt_s:.0f} Hz")
    r = math.exp(-zeta * w * dt_s)
    a1 = 2.0 * r * math.cos(w * dt_s * math.sqrt(1.0 - zeta * zeta))
    a2 = -r * r
    # stationary variance: the energy of the impulse response (decays as r^k)
    steps = int(min(10_000_000, max(1000, 40.0 / max(1e-12, 1.0 - r))))
    h = np.zeros(steps)
    y1 = y2 = 0.0
    for k in range(steps):
        y = a1 * y1 + a2 * y2 + (1.0 if k == 0 else (-1.0 if k == 1 else 0.0))
        h[k] = y
        y1, y2 = y, y1
    return (a1, a2, 1.0 / math.sqrt(float(np.sum(h * h))))


@njit(cache=True)
def resonator_step(ar, state, w):
    """One step of resonator_coefficients' filter: coefficients ``ar`` (a1, a2, gain), state
    (y_{k-1}, y_{k-2}, w_{k-1}) updated in place; returns y_k. White (a1 = a2 = 0): y_k = w_k."""
    if ar[0] == 0.0 and ar[1] == 0.0:
        return ar[2] * w
    y = ar[0] * state[0] + ar[1] * state[1] + ar[2] * (w - state[2])
    state[1] = state[0]
    state[0] = y
    state[2] = w
    return y
