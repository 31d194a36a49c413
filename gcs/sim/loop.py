"""Compiled closed-loop kernels of `gcs sim`: the law against the nominal model, chunk by chunk.

Two kernels share the law (gcs.control.law) and the physics (flightkit.physics):

* `run_sampled`: what a flight computer does. The law runs every `ctrl_every` plant steps on the
  sampled state, its outputs are held (zero-order hold) while the plant is integrated by RK4
  (then each airframe's linear drag, `TeamState.drag_per_s`, as an exact decay), and
  its own states (mhat, rhohat) are integrated by forward Euler over the control period; in
  rates mode rhohat is held (the rate loop, not the torque (26), turns the command into torque).
* `run_oracle`: the verification mode (docs/reproducing-the-paper.md): the law is evaluated
  inside every RK4 stage with the exact u', u'' (docs/control-law.md), which use the TRUE masses;
  tests only.

Both advance the state arrays in place and write log rows every `log_every` plant steps, so
the Python caller can run a long flight in chunks and show progress between them. The graph is
the law's edge list (gcs.control.formation.EdgeList), so a law step costs O(n + m) for m edges.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from flightkit.physics import derivatives as plant_derivatives
from flightkit.physics import orthonormalise, rk4_step
from gcs.control.derivatives import force_derivatives, levant_advance
from gcs.control.formation import reference_velocity
from gcs.control.geometry import is_nonsingular
from gcs.control.law import (
    DERIVATIVE_LEVANT,
    TeamMeasurement,
    attitude_stage,
    position_stage,
)
from gcs.sim.link import deliver, predict_to_act, receive, record, send
from gcs.sim.noise import add_telemetry_errors, recorded_position


class TeamState(NamedTuple):
    """The team's true state (advanced in place), its mass drops (the faults) and its airframes'
    linear drag."""

    p: np.ndarray
    v: np.ndarray
    rot: np.ndarray
    w: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    drop_step: np.ndarray  # plant step of each vehicle's mass drop, -1 for none
    drop_factor: np.ndarray
    drag_per_s: np.ndarray  # (n,) linear drag -m k v in the world frame [1/s]; 0: none


class LawInputs(NamedTuple):
    """The law's states (mhat, rhohat: advanced in place) and its fixed inputs."""

    mhat: np.ndarray
    rhohat: np.ndarray
    nominal_mass: np.ndarray
    graph: object  # gcs.control.formation.EdgeList
    offsets: np.ndarray
    ref_c: np.ndarray
    ref_a: np.ndarray
    ref_w: np.ndarray
    ref_ph: np.ndarray
    gains: object  # gcs.control.law's gains tuple
    adaptive: bool


class SampledLoop(NamedTuple):
    """What the sampled kernel keeps between chunks beside the law: the derivative's method
    and Levant state, the mode and rate loop, the held outputs, the last tick's diagnostics."""

    derivative: int
    levant_state: np.ndarray
    u_prev: np.ndarray
    levant_l: float
    levant_h: float
    mode: int
    rate_loop_gain: float
    thrust_hold: np.ndarray
    torque_hold: np.ndarray
    rate_cmd: np.ndarray
    diag: np.ndarray
    rc_hold: np.ndarray  # (n, 3, 3) the command attitude the vehicle holds (attitude mode)
    attitude_gain: np.ndarray  # (3,) the onboard attitude loop's P gains [1/s] (attitude mode)


class OracleState(NamedTuple):
    """The closed-loop state the verification mode integrates: the team's p, v, R, omega and the
    law's mhat, rhohat (one RK4 stage's, or the team's and the law's own arrays)."""

    p: np.ndarray
    v: np.ndarray
    rot: np.ndarray
    w: np.ndarray
    mhat: np.ndarray
    rhohat: np.ndarray


class OnboardResponse(NamedTuple):
    """An autopilot's own loops as gcs/control/cascade.py's recorded response models, flown on
    the true plant: each body rate follows the rate command through its second order (roll,
    pitch) or first order (yaw) after a dead time, the thrust its command through a first-order
    lag. `active` False: the idealised loops (_rate_loop, no thrust lag)."""

    active: bool
    zeta: float
    wn: float
    yaw_tau: float
    dead_steps: int  # roll/pitch dead time in plant steps
    yaw_dead_steps: int
    thrust_alpha: float  # 1 - exp(-dt / tau_T): the thrust lag per plant step
    track_gain: float  # how hard the torque makes the body rates follow the reference [1/s]
    ref: np.ndarray  # (n, 3) the reference body rates
    ref_dot: np.ndarray  # (n, 3)
    history: np.ndarray  # (L, n, 3) rate commands of the last L plant steps (the dead times)
    thrust_applied: np.ndarray  # (n,)



MODE_ACTUATORS = 0  #: the paper's torque (26) is applied directly
MODE_RATES = 1  #: the body-rate command is tracked by an idealised onboard rate loop
#: the command attitude R^c is tracked by an onboard P attitude loop feeding that rate loop
MODE_ATTITUDE = 2

#: Indices of the per-sample log columns written by the kernels (per vehicle).
LOG_FIELDS = (
    "px",
    "py",
    "pz",
    "vx",
    "vy",
    "vz",
    "attitude_error",
    "omega_error",
    "mass_estimate",
    "mass_true",
    "jx",
    "jy",
    "jz",
    "thrust",
    "ux",
    "uy",
    "uz",
)
N_LOG = len(LOG_FIELDS)


@njit(cache=True)
def _acceleration(rotation, thrust_n, mass_kg, g):
    """World acceleration -g e3 + T R e3 / m of every vehicle (what an IMU + attitude gives)."""
    n = rotation.shape[0]
    acc = np.empty((n, 3))
    for i in range(n):
        for k in range(3):
            acc[i, k] = thrust_n[i] * rotation[i, k, 2] / mass_kg[i]
        acc[i, 2] -= g
    return acc


@njit(cache=True)
def _add_drag(acc, v, drag_per_s):
    """The drag -k v each vehicle's accelerometer feels, added to its world acceleration acc."""
    for i in range(acc.shape[0]):
        if drag_per_s[i] > 0.0:
            for k in range(3):
                acc[i, k] -= drag_per_s[i] * v[i, k]


@njit(cache=True)
def plant_step(p, v, rot, w, thrust_n, torque_nm, mass, inertia, drag_per_s, dt_s):
    """Advance the team's true state by one plant step in place: RK4 of eqs (6)-(9) under the
    held thrust and torque (flightkit.physics.rk4_step), then each airframe's linear drag -m k v
    as the exact decay v exp(-k dt) (the emulator's plant splits the step the same way)."""
    rk4_step(p, v, rot, w, thrust_n, torque_nm, mass, inertia, dt_s)
    for i in range(v.shape[0]):
        if drag_per_s[i] > 0.0:
            decay = math.exp(-drag_per_s[i] * dt_s)
            for k in range(3):
                v[i, k] *= decay


@njit(cache=True)
def _norms(a):
    """Row norms (n,) of an (n, 3) array."""
    return np.sqrt((a * a).sum(axis=1))


@njit(cache=True)
def _write_log(log, row, p, v, tr_err, we_norm, kappa, mass, rhohat, thrust_n, u):
    n = p.shape[0]
    for i in range(n):
        for k in range(3):
            log[row, i, k] = p[i, k]
            log[row, i, 3 + k] = v[i, k]
            log[row, i, 10 + k] = rhohat[i, k]
            log[row, i, 14 + k] = u[i, k]
        log[row, i, 6] = tr_err[i]
        log[row, i, 7] = we_norm[i]
        log[row, i, 8] = kappa[i]
        log[row, i, 9] = mass[i]
        log[row, i, 13] = thrust_n[i]


@njit(cache=True)
def _apply_mass_drops(step, drop_step, drop_factor, mass):
    for i in range(mass.shape[0]):
        if drop_step[i] == step:
            mass[i] *= drop_factor[i]


@njit(cache=True)
def _rate_loop(i, w, inertia, rate_loop_gain, rate_cmd, torque_hold):
    """Idealised onboard rate loop of vehicle i: first-order tracking of the rate command with
    gyroscopic compensation, as a well-tuned autopilot would do (at the plant rate)."""
    jx, jy, jz = inertia[i, 0], inertia[i, 1], inertia[i, 2]
    wx, wy, wz = w[i, 0], w[i, 1], w[i, 2]
    torque_hold[i, 0] = jx * rate_loop_gain * (rate_cmd[i, 0] - wx) + (jz - jy) * wy * wz
    torque_hold[i, 1] = jy * rate_loop_gain * (rate_cmd[i, 1] - wy) + (jx - jz) * wz * wx
    torque_hold[i, 2] = jz * rate_loop_gain * (rate_cmd[i, 2] - wz) + (jy - jx) * wx * wy


@njit(cache=True)
def _attitude_loop(i, rot, rc_hold, gain, rate_cmd):
    """Onboard attitude loop of vehicle i: body rates -gain * eps / 2 toward the held R^c, eps
    = vee(R^e - R^eT) of R^e = R^cT R (2 sin(angle) about the error's axis)."""
    rc, r = rc_hold[i], rot[i]

    def re(a, b):  # (R^cT R)[a, b]
        return rc[0, a] * r[0, b] + rc[1, a] * r[1, b] + rc[2, a] * r[2, b]

    rate_cmd[i, 0] = -0.5 * gain[0] * (re(2, 1) - re(1, 2))
    rate_cmd[i, 1] = -0.5 * gain[1] * (re(0, 2) - re(2, 0))
    rate_cmd[i, 2] = -0.5 * gain[2] * (re(1, 0) - re(0, 1))


@njit(cache=True)
def _response_loop(i, step, dt_s, w, inertia, rate_cmd, torque_hold, r):
    """Vehicle i's rate loop as the response model: advance the reference by one plant step on
    the delayed command and make the torque follow it (with gyroscopic compensation)."""
    depth = r.history.shape[0]
    for k in range(3):
        r.history[step % depth, i, k] = rate_cmd[i, k]
    for k in range(3):
        dead = r.yaw_dead_steps if k == 2 else r.dead_steps
        u = r.history[max(step - dead, 0) % depth, i, k] if step - dead >= 0 else 0.0
        if k == 2:
            acc = (u - r.ref[i, k]) / r.yaw_tau
        else:
            acc = r.wn * r.wn * (u - r.ref[i, k]) - 2.0 * r.zeta * r.wn * r.ref_dot[i, k]
            r.ref_dot[i, k] += dt_s * acc
        r.ref[i, k] += dt_s * (r.ref_dot[i, k] if k < 2 else acc)
        if k == 2:
            r.ref_dot[i, k] = acc
    jx, jy, jz = inertia[i, 0], inertia[i, 1], inertia[i, 2]
    wx, wy, wz = w[i, 0], w[i, 1], w[i, 2]
    g = r.track_gain
    torque_hold[i, 0] = jx * (r.ref_dot[i, 0] + g * (r.ref[i, 0] - wx)) + (jz - jy) * wy * wz
    torque_hold[i, 1] = jy * (r.ref_dot[i, 1] + g * (r.ref[i, 1] - wy)) + (jx - jz) * wz * wx
    torque_hold[i, 2] = jz * (r.ref_dot[i, 2] + g * (r.ref[i, 2] - wz)) + (jy - jx) * wx * wy


@njit(cache=True)
def run_sampled(first_step, n_steps, dt_s, ctrl_every, log_every, team, law, loop, link, onboard,
                noise, log, log_row0):
    """Advance plant and law by `n_steps` plant steps from step index `first_step`.

    `diag` (n, 6) carries the last tick's (attitude error, |omega^e|, kappa, ux, uy, uz) between
    chunks. Returns the minimum u_z seen and the count of singular command forces. ``team``,
    ``law``, ``loop``, ``link``, ``onboard``: `TeamState`, `LawInputs`, `SampledLoop`,
    gcs.sim.link.SimLink (inactive: the law reads the true state and its setpoints act at once),
    `OnboardResponse` (inactive: the idealised rate loop, no thrust lag), gcs.sim.noise.SimNoise
    (inactive: the law reads the state exactly).
    """
    p, v, rot, w, mass, inertia, drop_step, drop_factor, drag_per_s = team
    (mhat, rhohat, nominal_mass, graph, offsets, ref_c, ref_a, ref_w, ref_ph, gains,
     adaptive) = law
    (derivative, levant_state, u_prev, levant_l, levant_h, mode, rate_loop_gain, thrust_hold,
     torque_hold, rate_cmd, diag, rc_hold, attitude_gain) = loop
    n = p.shape[0]
    ctrl_dt = ctrl_every * dt_s
    min_uz = np.inf
    singular = 0
    tr_err = diag[:, 0].copy()
    we_norm = diag[:, 1].copy()
    kappa = diag[:, 2].copy()
    u = diag[:, 3:6].copy()
    for step in range(first_step, first_step + n_steps):
        _apply_mass_drops(step, drop_step, drop_factor, mass)
        t = step * dt_s
        # the thrust acting on the plant: the held command, or its lagged response
        thrust_now = onboard.thrust_applied if onboard.active else thrust_hold
        if link.active:
            record(link, step, p, v, rot, w, thrust_now, mass, drag_per_s, gains.gravity_mps2)
        if step % ctrl_every == 0:
            if link.active:
                mp, mv, mrot, mw, macc = receive(link, step, step // ctrl_every)
                if link.predict:
                    predict_to_act(mp, mv, mrot, mw, macc, link, step, dt_s)
            else:
                mp, mv, mrot, mw = p, v, rot, w
                # the accelerometer's reading in the world: specific force under the held
                # thrust and the drag, minus g e3
                macc = _acceleration(rot, thrust_now, mass, gains.gravity_mps2)
                _add_drag(macc, v, drag_per_s)
            if noise.active:
                mp, mv, mrot, mw, macc = add_telemetry_errors(
                    noise, step // ctrl_every, mp, mv, mrot, mw, macc, gains.gravity_mps2, ctrl_dt)
            ref = reference_velocity(t, ref_c, ref_a, ref_w, ref_ph)
            stage = position_stage(
                mp, mv, mrot, mhat, nominal_mass, graph, offsets, ref, gains, adaptive
            )
            u, kappa, t_n, mhat_rate = stage.force_n, stage.kappa, stage.thrust_n, stage.mhat_rate
            ok = is_nonsingular(u)
            for i in range(n):
                if not ok[i]:
                    singular += 1
                min_uz = min(min_uz, u[i, 2])
            if singular > 0:
                return min_uz, singular
            if derivative == DERIVATIVE_LEVANT:
                if step == 0:
                    for i in range(n):
                        for k in range(3):
                            levant_state[i, k, 0] = u[i, k]
                            levant_state[i, k, 1] = 0.0
                            levant_state[i, k, 2] = 0.0
                else:
                    levant_advance(levant_state, u_prev, u, ctrl_dt, levant_h, levant_l)
                u_prev[:, :] = u
                du = levant_state[:, :, 1].copy()
                ddu = levant_state[:, :, 2].copy()
            else:
                meas = TeamMeasurement(mp, mv, macc, mrot, mw)
                du, ddu = force_derivatives(
                    meas, stage, mhat, 1.0 / kappa, graph, ref, gains, adaptive
                )
            rc, wc, dwc, tau, rho_rate, omega_cmd, eps, tr_err, we = attitude_stage(
                mrot, mw, u, du, ddu, rhohat, gains, adaptive, np.zeros(u.shape[0])
            )
            we_norm = _norms(we)
            if link.active:
                send(link, step, step // ctrl_every, t_n, omega_cmd, tau, rc)
            else:
                thrust_hold[:] = t_n
                torque_hold[:, :] = tau
                rate_cmd[:, :] = omega_cmd
                rc_hold[:, :, :] = rc
            for i in range(n):
                mhat[i] += ctrl_dt * mhat_rate[i]
                if mode == MODE_ACTUATORS:  # rhohat acts only through the torque (26)
                    for k in range(3):
                        rhohat[i, k] += ctrl_dt * rho_rate[i, k]
        if link.active:
            deliver(link, step, thrust_hold, rate_cmd, torque_hold, rc_hold)
        if mode != MODE_ACTUATORS:
            for i in range(n):
                if mode == MODE_ATTITUDE:
                    _attitude_loop(i, rot, rc_hold, attitude_gain, rate_cmd)
                if onboard.active:
                    _response_loop(i, step, dt_s, w, inertia, rate_cmd, torque_hold, onboard)
                else:
                    _rate_loop(i, w, inertia, rate_loop_gain, rate_cmd, torque_hold)
        if onboard.active:
            for i in range(n):
                onboard.thrust_applied[i] += onboard.thrust_alpha * (
                    thrust_hold[i] - onboard.thrust_applied[i])
        if step % log_every == 0:
            _write_log(
                log,
                log_row0 + (step - first_step) // log_every,
                # with telemetry errors, the positions as gcs fly records them
                recorded_position(noise, step // ctrl_every, p, v) if noise.active else p,
                v,
                tr_err,
                we_norm,
                kappa,
                mass,
                rhohat,
                thrust_hold,
                u,
            )
        plant_step(p, v, rot, w, thrust_now, torque_hold, mass, inertia, drag_per_s, dt_s)
    for i in range(n):
        diag[i, 0] = tr_err[i]
        diag[i, 1] = we_norm[i]
        diag[i, 2] = kappa[i]
        for k in range(3):
            diag[i, 3 + k] = u[i, k]
    return min_uz, singular


@njit(cache=True)
def _oracle_rates(t, x, team, law):
    """Closed-loop vector field with the exact u', u'' (the oracle of docs/control-law.md) at
    time ``t`` and state ``x`` (`OracleState`), which stands for the state fields of ``team``
    (`TeamState`: its mass and inertia are read) and ``law`` (`LawInputs`: its fixed inputs are
    read). Returns the state derivatives and the law's diagnostics at this state."""
    p, v, rot, w, mhat, rhohat = x
    mass, inertia = team.mass, team.inertia
    gains, adaptive, graph = law.gains, law.adaptive, law.graph
    ref = reference_velocity(t, law.ref_c, law.ref_a, law.ref_w, law.ref_ph)
    stage = position_stage(
        p, v, rot, mhat, law.nominal_mass, graph, law.offsets, ref, gains, adaptive
    )
    u, kappa, t_n, mhat_rate = stage.force_n, stage.kappa, stage.thrust_n, stage.mhat_rate
    acc = _acceleration(rot, t_n, mass, gains.gravity_mps2)
    meas = TeamMeasurement(p, v, acc, rot, w)
    du, ddu = force_derivatives(meas, stage, mhat, 1.0 / mass, graph, ref, gains, adaptive)
    rc, wc, dwc, tau, rho_rate, omega_cmd, eps, tr_err, we = attitude_stage(
        rot, w, u, du, ddu, rhohat, gains, adaptive, np.zeros(u.shape[0])
    )
    dp, dv, drot, dw = plant_derivatives(p, v, rot, w, t_n, tau, mass, inertia)
    return dp, dv, drot, dw, mhat_rate, rho_rate, u, kappa, t_n, tr_err, we


@njit(cache=True)
def _advanced(x, k, c):
    """The state x + c k (`OracleState`) of an RK4 stage, k the rates `_oracle_rates` returned."""
    return OracleState(x.p + c * k[0], x.v + c * k[1], x.rot + c * k[2], x.w + c * k[3],
                       x.mhat + c * k[4], x.rhohat + c * k[5])


@njit(cache=True)
def run_oracle(first_step, n_steps, dt_s, log_every, team, law, log, log_row0):
    """Classic RK4 on the full closed-loop state (p, v, R, omega, mhat, rhohat) with the law
    evaluated in every stage (exact derivatives, true masses), on the paper's drag-free model
    (the team's drag_per_s is not read). Returns the minimum u_z.
    ``team``, ``law``: `TeamState`, `LawInputs`."""
    p, v, rot, w, mass, _inertia, drop_step, drop_factor, _drag = team
    mhat, rhohat = law.mhat, law.rhohat
    x = OracleState(p, v, rot, w, mhat, rhohat)  # the arrays themselves: advanced in place
    min_uz = np.inf
    for step in range(first_step, first_step + n_steps):
        _apply_mass_drops(step, drop_step, drop_factor, mass)
        t = step * dt_s
        k1 = _oracle_rates(t, x, team, law)
        for i in range(p.shape[0]):
            min_uz = min(min_uz, k1[6][i, 2])
        if step % log_every == 0:
            _write_log(
                log,
                log_row0 + (step - first_step) // log_every,
                p,
                v,
                k1[9],
                _norms(k1[10]),
                k1[7],
                mass,
                rhohat,
                k1[8],
                k1[6],
            )
        h = 0.5 * dt_s
        k2 = _oracle_rates(t + h, _advanced(x, k1, h), team, law)
        k3 = _oracle_rates(t + h, _advanced(x, k2, h), team, law)
        k4 = _oracle_rates(t + dt_s, _advanced(x, k3, dt_s), team, law)
        c = dt_s / 6.0
        p += c * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        v += c * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        rot += c * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        w += c * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        mhat += c * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        rhohat += c * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
        orthonormalise(rot)
    return min_uz
