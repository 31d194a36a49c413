"""Is the law stable on a given autopilot, over a given link? The cascade criterion. Pure.

In `rates` and `attitude` mode the autopilot closes the innermost loop, and the paper's loops sit
on top of it: the position loop (21)-(23) commands a tilt, the tilt is what the autopilot's loops
deliver some time later. The paper designs its gains for a vehicle that tracks its attitude
command at once; a real autopilot does not (PX4 v1.16 SIH: roll-rate t63 87 ms with 37 %
overshoot, yaw rate 0.82 of a 1 rad/s step after 0.6 s; recorded: docs/emulator.md). With the
paper's gains (c_p 4, alpha_p 2) and k_eps 8 that lag closes two limit cycles on the px4
personality (docs/gcs.md, "Control modes"): the ground station's attitude loop at ~2.4 Hz
(roll/pitch coning, the body-rate limit active on 95 % of the setpoints, noise or not) and the
yaw loop, saturated at its own limit.

The criterion linearises each loop about hover and checks it in continuous time with the delays
written out (exact e^{-sT} on the frequency grid, Pade (3,3) for the poles):

* autopilot rate loop, per roll/pitch axis: G_r(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-s T_r};
  yaw: G_y(s) = e^{-s T_y} / (tau_y s + 1); thrust: e^{-s T_r} / (tau_T s + 1). The defaults per
  autopilot (`PX4_RESPONSE`, `ARDUPILOT_RESPONSE`) are fits to the recorded rate doublets.
* link: d_up = link delay + h/2 (the tick's zero-order hold), d_down = link delay + h/2 (the
  telemetry sample's age at the tick).
* rates mode, ground-station attitude loop (eps ~ 2 theta, omega_cmd = omega^c - k_eps eps):
  L_att = 2 k_eps G_r e^{-s (d_up + d_down)} / s; yaw the same with k_eps_yaw and G_y. The tilt
  then follows its command as
  T(s) = G_r e^{-s d_up} (s + 2 k_eps) / (s + 2 k_eps G_r e^{-s (d_up + d_down)})
  (the command's own rate, omega^c, is the feed-forward s).
* attitude mode, the autopilot's attitude P law on board: T(s) = P G_r e^{-s d_up} / (s + P G_r).
* position loop, per eigenvalue lambda of the team's graph Laplacian (lambda = 0: the common
  velocity loop), in the linear range of sat: a = -alpha_p (c_p lambda e + 2 e'), so
  L_pos = alpha_p (c_p lambda + 2 s) / s^2 e^{-s d_down} T(s); vertically with the thrust lag.

With delay compensation (`fly.predict`, gcs/control/predict.py) the law reads each state predicted
over the horizon tau = d_down + link delay (the sample's age plus the uplink) from the sample and
its derivatives: the attitude by its rates, the position by its velocity and acceleration, the
velocity by its acceleration. Linearised, a measured signal x(t - d_down) becomes
x(t - d_down) + tau x'(t - d_down) (+ tau^2 x''(t - d_down) / 2 for the position), so each
feedback path gains the lead P1 = 1 + s tau (attitude, velocity) or P2 = 1 + s tau + s^2 tau^2 / 2
(position): L_att = 2 k_eps G_r e^{-s (d_up + d_down)} P1 / s, the tilt's inner loop likewise,
and L_pos = alpha_p (c_p lambda P2 + 2 s P1) / s^2 e^{-s d_down} T(s). The lead cancels the
delay's phase lag to second order at low frequency and raises the loop gain above 1 / tau; the
criterion weighs both.

A loop passes when its closed loop is stable (every pole in the open left half plane) and its
modulus margin min_w |1 + L(jw)| is at least `MIN_MODULUS_MARGIN` (0.4: gain margin >= 1/(1 - 0.4)
= 1.67 and phase margin >= 2 asin(0.2) = 23 deg whatever the number of crossings).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gcs.control.modes import ControlMode

MIN_MODULUS_MARGIN = 0.4
MAX_EIGENVALUES = 16  # distinct Laplacian eigenvalues checked (large teams: a spread of them)
#: the modes the criterion covers (the law's setpoint goes through the autopilot's own loops), in
#: the order `verdict` names gains that pass
CASCADE_MODES = (ControlMode.RATES, ControlMode.ATTITUDE)
_FREQ_RADPS = np.logspace(-2, 3, 4000)
_S = 1j * _FREQ_RADPS  # the grid every loop's frequency response is evaluated on


@dataclass(frozen=True, slots=True)
class AutopilotResponse:
    """How an autopilot's own loops answer a setpoint (module docstring for the model)."""

    rate_damping: float  # zeta of the roll/pitch rate loop
    rate_natural_radps: float  # wn of the roll/pitch rate loop
    rate_dead_time_s: float  # T_r, from the setpoint's arrival
    yaw_time_constant_s: float  # tau_y of the yaw-rate loop
    yaw_dead_time_s: float  # T_y
    attitude_p_per_s: float  # roll/pitch attitude P gain (attitude mode)
    thrust_time_constant_s: float  # tau_T of the thrust (motor) response
    source: str = ""  # where the numbers come from (one line)


#: PX4 v1.16.0 SIH, default tuning: the second order + dead time that fits the four recorded roll
#: and pitch doublets over their whole traces in least squares
#: (benchmarks/calibration/fit_rate_response.py: rms 0.065 rad/s, against 0.132 for zeta 0.30,
#: wn 14.7 read off the noisy roll step's 37 % peak, which overstates the resonance the position
#: loop meets; the dead time stays SIH's 4 ms lockstep, the fit's 4.9 ms lying between roll's 7.8
#: and pitch's 2.1); first-order + dead-time fit of the yaw doublet (99 ms / 590 ms), MC_ROLL_P
#: 6.5, SIH_T_TAU 0.05 s.
PX4_RESPONSE = AutopilotResponse(
    rate_damping=0.73, rate_natural_radps=19.1, rate_dead_time_s=0.004,
    yaw_time_constant_s=0.59, yaw_dead_time_s=0.099, attitude_p_per_s=6.5,
    thrust_time_constant_s=0.05,
    source="PX4 v1.16.0 SIH default tuning (recorded rate doublets)")
#: ArduCopter 4.7.0-dev SITL, default tuning: roll doublet 29/44/54 ms, 4 % overshoot; yaw
#: 148 ms / 590 ms; ATC_ANG_RLL_P 4.5; thrust steps followed after ~2.5 ms.
ARDUPILOT_RESPONSE = AutopilotResponse(
    rate_damping=0.72, rate_natural_radps=86.7, rate_dead_time_s=0.023,
    yaw_time_constant_s=0.59, yaw_dead_time_s=0.148, attitude_p_per_s=4.5,
    thrust_time_constant_s=0.0025,
    source="ArduCopter 4.7.0-dev SITL default tuning (recorded rate doublets)")
#: `vehicle-emu --autopilot nominal` (the paper's model, an inertia-scaled 1 kHz rate loop): the
#: PX4 doublets replayed into it give roll t10/t63/t90 10/30/60 ms, 2 % overshoot, yaw t63 99 ms;
#: no motor lag unless the team file sets one.
NOMINAL_RESPONSE = AutopilotResponse(
    rate_damping=0.81, rate_natural_radps=63.4, rate_dead_time_s=0.002,
    yaw_time_constant_s=0.088, yaw_dead_time_s=0.010, attitude_p_per_s=6.5,
    thrust_time_constant_s=0.002,
    source="vehicle-emu --autopilot nominal (replayed PX4 doublets)")


@dataclass(frozen=True, slots=True)
class CascadeGains:
    """The gains the cascade depends on."""

    alpha_p: float
    c_p: float
    k_eps: float
    k_eps_yaw: float

    def describe(self, mode: ControlMode) -> str:
        position = f"alpha_p {self.alpha_p:g}, c_p {self.c_p:g}"
        if mode == ControlMode.RATES:
            return f"k_eps {self.k_eps:g}, k_eps_yaw {self.k_eps_yaw:g}, {position}"
        return position


@dataclass(frozen=True, slots=True)
class LoopMargin:
    """One linearised loop: closed-loop stable?, its modulus margin and where it is smallest."""

    loop: str  # e.g. "attitude roll/pitch", "position lambda=4 horizontal"
    stable: bool
    modulus_margin: float
    at_radps: float

    def ok(self) -> bool:
        return self.stable and self.modulus_margin >= MIN_MODULUS_MARGIN

    def describe(self) -> str:
        state = "stable" if self.stable else "UNSTABLE"
        return (f"{self.loop}: {state}, modulus margin {self.modulus_margin:.2f} at "
                f"{self.at_radps:.3g} rad/s")


# --- rational functions: (num, den), coefficient arrays, highest power first ------------------


def _pade(delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(3,3) Pade approximant of e^{-s T}."""
    t = delay_s
    c = np.array([t ** 3 / 120.0, t ** 2 / 10.0, t / 2.0, 1.0])
    return c * np.array([-1.0, 1.0, -1.0, 1.0]), c


def _pmul(a, b):
    """Product of two polynomials (np.polymul without its poly1d round trip, which costs more
    than the product itself; leading zeros are kept, `margin` trims them)."""
    return np.convolve(a, b)


def _padd(a, b):
    """Sum of two polynomials (highest power first)."""
    if len(a) < len(b):
        a, b = b, a
    out = np.array(a, dtype=float)
    out[len(a) - len(b):] += b
    return out


def _mul(*parts):
    num, den = np.array([1.0]), np.array([1.0])
    for n, d in parts:
        num, den = _pmul(num, n), _pmul(den, d)
    return num, den


def _closed(forward, feedback):
    """forward / (1 + forward feedback) as a rational function."""
    fn, fd = forward
    bn, bd = feedback
    return _pmul(fn, bd), _padd(_pmul(fd, bd), _pmul(fn, bn))


def _on_grid(f: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
    """f, its values on the frequency grid computed once: a large team's position loops (two
    per eigenvalue) share the tilt, thrust, delay and lead responses."""
    value: list[np.ndarray] = []

    def at(s: np.ndarray) -> np.ndarray:
        if s is not _S:
            return f(s)
        if not value:
            value.append(f(s))
        return value[0]

    return at


class _Loop:
    """An open loop L as a callable frequency response (exact delays) and a rational function
    (Pade delays) whose closed loop's poles decide stability."""

    def __init__(self, rational, response):
        self.rational, self.response = rational, response

    def margin(self, name: str) -> LoopMargin:
        num, den = self.rational
        char = _padd(den, num)
        char = np.trim_zeros(char, "f")
        roots = np.roots(char) if len(char) > 1 else np.array([])
        stable = bool(np.all(roots.real < -1e-9))
        dist = np.abs(1.0 + self.response(_S))
        k = int(np.argmin(dist))
        return LoopMargin(name, stable, float(dist[k]), float(_FREQ_RADPS[k]))


def _rate_loop(r: AutopilotResponse):
    wn, z = r.rate_natural_radps, r.rate_damping
    rational = _mul((np.array([wn * wn]), np.array([1.0, 2.0 * z * wn, wn * wn])),
                    _pade(r.rate_dead_time_s))
    return rational, lambda s: wn * wn / (s * s + 2 * z * wn * s + wn * wn) * np.exp(
        -s * r.rate_dead_time_s)


def _yaw_loop(r: AutopilotResponse):
    rational = _mul((np.array([1.0]), np.array([r.yaw_time_constant_s, 1.0])),
                    _pade(r.yaw_dead_time_s))
    return rational, lambda s: np.exp(-s * r.yaw_dead_time_s) / (r.yaw_time_constant_s * s + 1)


@functools.lru_cache(maxsize=32)
def _delay(t):
    return _pade(t), _on_grid(lambda s: np.exp(-s * t))


@functools.lru_cache(maxsize=32)
def _lead(tau: float, order: int):
    """The predictor's lead on a delayed signal: 1 + s tau (+ s^2 tau^2 / 2 for order 2)."""
    coeffs = [1.0, tau] if order == 1 else [1.0, tau, 0.5 * tau * tau]
    poly = np.array(coeffs[::-1])
    return (poly, np.array([1.0])), _on_grid(lambda s: np.polyval(poly, s))


def _attitude_loop(k: float, plant, d_loop: float, tau: float = 0.0) -> _Loop:
    """L = 2 k plant e^{-s d} P1 / s (the ground station's attitude loop of rates mode; P1 the
    predictor's lead over tau, 1 without prediction)."""
    (pr, pf), (dr, df), (lr, lf) = plant, _delay(d_loop), _lead(tau, 1)
    rational = _mul((np.array([2.0 * k]), np.array([1.0, 0.0])), pr, dr, lr)
    return _Loop(rational, lambda s: 2.0 * k * pf(s) * df(s) * lf(s) / s)


def _tilt_rates(k: float, r: AutopilotResponse, d_up: float, d_down: float, tau: float = 0.0):
    """theta / theta_c in rates mode (module docstring; the inner loop's feedback with the
    predictor's lead P1 over tau)."""
    (gr, gf), (ur, uf), (lr, lf0) = _rate_loop(r), _delay(d_up), _delay(d_up + d_down)
    (pn, _), pf = _lead(tau, 1)
    (gn, gd), (un, ud), (ln, ld) = gr, ur, lr
    ln = _pmul(ln, pn)

    def lf(s):
        return lf0(s) * pf(s)

    # T = G U (s + 2k) / (s + 2k G L) = gn un (s + 2k) ld / (ud (s gd ld + 2k gn ln))
    num = _pmul(_pmul(gn, un), _pmul(np.array([1.0, 2.0 * k]), ld))
    den = _pmul(ud, _padd(_pmul(np.array([1.0, 0.0]), _pmul(gd, ld)),
                                    2.0 * k * _pmul(gn, ln)))
    rational = (num, den)

    def f(s):
        g = gf(s)
        return g * uf(s) * (s + 2.0 * k) / (s + 2.0 * k * g * lf(s))

    return rational, f


def _tilt_attitude(r: AutopilotResponse, d_up: float):
    """theta / theta_c in attitude mode: P G_r / (s + P G_r), after the uplink delay."""
    (gr, gf), (ur, uf) = _rate_loop(r), _delay(d_up)
    p = r.attitude_p_per_s
    inner = _closed(_mul((np.array([p]), np.array([1.0, 0.0])), gr), (np.array([1.0]),
                                                                      np.array([1.0])))
    rational = _mul(inner, ur)
    return rational, lambda s: p * gf(s) / (s + p * gf(s)) * uf(s)


def _thrust(r: AutopilotResponse, d_up: float):
    (ur, uf) = _delay(d_up + r.rate_dead_time_s)
    rational = _mul((np.array([1.0]), np.array([r.thrust_time_constant_s, 1.0])), ur)
    return rational, lambda s: uf(s) / (r.thrust_time_constant_s * s + 1.0)


def _position_loop(g: CascadeGains, lam: float, tilt, d_down: float, tau: float = 0.0) -> _Loop:
    """L_pos (module docstring), with the predictor's leads over tau (none at tau 0)."""
    (tr, tf), (dr, df) = tilt, _delay(d_down)
    (p1, _), p1f = _lead(tau, 1)
    (p2, _), p2f = _lead(tau, 2)
    if lam == 0.0:  # the common mode: velocity feedback only, one integrator (s cancels)
        law = (2.0 * g.alpha_p * p1, np.array([1.0, 0.0]))
    else:
        law = (g.alpha_p * _padd(g.c_p * lam * p2, _pmul(np.array([2.0, 0.0]), p1)),
               np.array([1.0, 0.0, 0.0]))
    rational = _mul(law, dr, tr)
    return _Loop(rational, lambda s: g.alpha_p * (g.c_p * lam * p2f(s) + 2.0 * s * p1f(s))
                 / (s * s) * df(s) * tf(s))


def laplacian_eigenvalues(laplacian: np.ndarray) -> list[float]:
    """Distinct eigenvalues of the weighted graph Laplacian D - A (0 included)."""
    eig = np.sort(np.linalg.eigvalsh(np.asarray(laplacian, dtype=float)))
    tiny = 1e-9 * max(1.0, float(eig[-1])) if eig.size else 0.0
    out: list[float] = []
    for value in eig:
        value = float(value) if value > tiny else 0.0  # the common mode is exactly 0
        if not out or value - out[-1] > 1e-6:
            out.append(value)
    if len(out) > MAX_EIGENVALUES:  # a large team: 0, the extremes and evenly spaced ones
        pick = np.linspace(1, len(out) - 1, MAX_EIGENVALUES - 1).round().astype(int)
        out = [0.0] + [out[k] for k in sorted(set(pick.tolist()))]
    return out


def prediction_horizon_s(tick_rate_hz: float, link_delay_s: float, predicted: bool) -> float:
    """tau of the module docstring: the sample's age (link delay + h / 2) plus the uplink."""
    return 2.0 * link_delay_s + 0.5 / tick_rate_hz if predicted else 0.0


def cascade_margins(mode: ControlMode, gains: CascadeGains, response: AutopilotResponse,
                    eigenvalues: Sequence[float], tick_rate_hz: float,
                    link_delay_s: float, predicted: bool = False) -> list[LoopMargin]:
    """Every loop of `mode` (CASCADE_MODES: rates or attitude) on this autopilot over this link;
    `predicted`: the law reads predicted states (fly.predict)."""
    h = 1.0 / tick_rate_hz
    d_up = link_delay_s + h / 2.0
    d_down = link_delay_s + h / 2.0
    tau = prediction_horizon_s(tick_rate_hz, link_delay_s, predicted)
    out: list[LoopMargin] = []
    if mode == ControlMode.RATES:
        out.append(_attitude_loop(gains.k_eps, _rate_loop(response), d_up + d_down, tau)
                   .margin("ground-station attitude loop, roll/pitch"))
        out.append(_attitude_loop(gains.k_eps_yaw, _yaw_loop(response), d_up + d_down, tau)
                   .margin("ground-station attitude loop, yaw"))
        tilt = _tilt_rates(gains.k_eps, response, d_up, d_down, tau)
    elif mode == ControlMode.ATTITUDE:
        tilt = _tilt_attitude(response, d_up)
    else:
        raise ValueError(f"no cascade criterion for mode {str(mode)!r}")
    inner_ok = all(m.ok() for m in out)
    thrust = _thrust(response, d_up)
    tilt, thrust = (tilt[0], _on_grid(tilt[1])), (thrust[0], _on_grid(thrust[1]))
    for lam in eigenvalues:
        label = "common velocity loop" if lam == 0.0 else f"formation mode lambda={lam:.3g}"
        if inner_ok:  # the tilt response is only meaningful on a stable attitude loop
            out.append(_position_loop(gains, lam, tilt, d_down, tau).margin(
                f"position loop, {label}, horizontal"))
        out.append(_position_loop(gains, lam, thrust, d_down, tau).margin(
            f"position loop, {label}, vertical"))
    return out


def passes(margins: Sequence[LoopMargin]) -> bool:
    return all(m.ok() for m in margins)


def worst(margins: Sequence[LoopMargin]) -> LoopMargin:
    """The failing loop with the smallest margin, else the smallest margin overall."""
    bad = [m for m in margins if not m.ok()]
    pool = bad or list(margins)
    return min(pool, key=lambda m: (m.stable, m.modulus_margin))


#: Candidates tried when the team file's gains fail: the attitude feedback of rates mode, and
#: alpha_p and c_p scaled down each on its own (c_p weighs the graph's largest eigenvalue).
_K_EPS = (8.0, 6.0, 4.0, 3.0, 2.0, 1.5, 1.0)
_K_YAW = (4.0, 2.0, 1.0, 0.5, 0.25)
_SCALES = (1.0, 0.75, 0.5, 0.35, 0.25, 0.15, 0.1)


def stable_gains(mode: ControlMode, gains: CascadeGains, response: AutopilotResponse,
                 eigenvalues: Sequence[float], tick_rate_hz: float,
                 link_delay_s: float, predicted: bool = False) -> CascadeGains | None:
    """The passing candidate with the stiffest position loop (largest alpha_p c_p, the loop's
    low-frequency gain, which sets how well it holds against disturbances), never stiffer than
    `gains` in any gain; None if none passes."""
    def ok(g: CascadeGains) -> bool:
        return passes(cascade_margins(mode, g, response, eigenvalues, tick_rate_hz,
                                      link_delay_s, predicted))

    inner = [(gains.k_eps, gains.k_eps_yaw)]
    if mode == ControlMode.RATES:  # the two attitude loops first: each depends on its own gain only
        loop = 2.0 * (link_delay_s + 0.5 / tick_rate_hz)
        tau = prediction_horizon_s(tick_rate_hz, link_delay_s, predicted)

        def attitude_ok(k: float, plant) -> bool:
            return _attitude_loop(k, plant, loop, tau).margin("").ok()

        kys = [k for k in _K_YAW if k <= gains.k_eps_yaw] or [gains.k_eps_yaw]
        ky = next((k for k in kys if attitude_ok(k, _yaw_loop(response))), None)
        ks = [k for k in _K_EPS if k <= gains.k_eps] or [gains.k_eps]
        ks = [k for k in ks if attitude_ok(k, _rate_loop(response))]
        if ky is None or not ks:
            return None
        inner = [(k, ky) for k in ks]
    scales = sorted(((a, c) for a in _SCALES for c in _SCALES), key=lambda p: (-p[0] * p[1], -p[0]))
    best: CascadeGains | None = None
    for k, ky in inner:
        for a, c in scales:
            g = CascadeGains(gains.alpha_p * a, gains.c_p * c, k, ky)
            if best is not None and g.alpha_p * g.c_p <= best.alpha_p * best.c_p:
                break
            if ok(g):
                best = g
                break
    return best


def verdict(mode: ControlMode, gains: CascadeGains, response: AutopilotResponse,
            eigenvalues: Sequence[float], tick_rate_hz: float, link_delay_s: float,
            autopilot: str, predicted: bool = False) -> tuple[bool, str]:
    """(passes, one line) for `mode` with `gains` on `autopilot` (its `response`); `predicted`:
    the law reads predicted states (fly.predict)."""
    margins = cascade_margins(mode, gains, response, eigenvalues, tick_rate_hz, link_delay_s,
                              predicted)
    w = worst(margins)
    where = (f"{mode} mode with {gains.describe(mode)} at {tick_rate_hz:g} Hz, link delay "
             f"{1e3 * link_delay_s:.0f} ms{' (compensated, fly.predict)' if predicted else ''}, "
             f"on {autopilot} ({response.source})")
    if passes(margins):
        return True, (f"{where}: every loop passes, smallest modulus margin "
                      f"{w.modulus_margin:.2f} ({w.loop})")
    line = (f"{where} is not stable enough: {w.describe()} (need stable and >= "
            f"{MIN_MODULUS_MARGIN:g})")
    fixes = []
    for other in CASCADE_MODES:
        g = stable_gains(other, gains, response, eigenvalues, tick_rate_hz, link_delay_s,
                         predicted)
        if g is not None:
            fixes.append(f"{other} mode with {g.describe(other)} (fly.{other})")
    for other in CASCADE_MODES if not fixes else ():  # the other fly.predict
        g = stable_gains(other, gains, response, eigenvalues, tick_rate_hz, link_delay_s,
                         not predicted)
        if g is not None:
            fixes.append(f"{other} mode with {g.describe(other)} (fly.{other}) and "
                         f"fly.predict {'false' if predicted else 'true'}")
    line += "; stable: " + " or ".join(fixes) if fixes else "; no candidate gains are stable"
    return False, line

