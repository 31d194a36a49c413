"""The link of `gcs sim`: what the ground station's law would read and when its setpoints act.

Each vehicle's link has a one-way delay d (sim.link_delay_s, rounded to plant steps, the same
both ways) and a loss probability q (sim.link_loss, each way, drawn per tick from sim.link_seed):

* down: at a control tick at plant step k the law receives vehicle i's state as it was at step
  k - d (position, velocity, attitude, body rates and the measured acceleration), unless that
  sample is lost; then it reads the last sample it did receive;
* up: the setpoint computed at step k acts from step k + d on (lost: the vehicle keeps the one
  it has); the vehicle's own loops (rate, attitude) run on its true state, undelayed;
* prediction (fly.predict, as gcs fly does it, gcs/control/predict.py): the law reads each received
  sample carried forward to the step its setpoint will act at, over the horizon
  h = (k + d - taken) dt clamped to [0, MAX_HORIZON_S]: p + v h + a h^2 / 2, v + a h, R exp(w h).

Before t = 0 the vehicles hover at their initial state, so the history starts filled with it.
With no delay and no loss the link is off and the loop reads the true state directly.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from gcs.control.predict import MAX_HORIZON_S

#: A sample's layout: position 0-2, velocity 3-5, R row-major 6-14, body rates 15-17,
#: measured acceleration (world, specific force minus g e3) 18-20.
SAMPLE = 21
#: A setpoint's layout: thrust 0, rate command 1-3, torque 4-6, command attitude R^c
#: row-major 7-15.
SETPOINT = 16
#: taken_step before the first sample (the first tick always receives one).
NOTHING = -(1 << 62)


class SimLink(NamedTuple):
    """The link's settings and state (advanced in place by the kernel)."""

    active: bool
    predict: bool
    delay_steps: np.ndarray  # (n,) int64, one-way, each way
    lost_down: np.ndarray  # (ticks, n) bool: vehicle i's sample of tick k is lost
    lost_up: np.ndarray  # (ticks, n) bool: the setpoint of tick k to vehicle i is lost
    history: np.ndarray  # (L, n, SAMPLE): the true state of the last L plant steps
    received: np.ndarray  # (n, SAMPLE): the last sample received
    taken_step: np.ndarray  # (n,) int64: the plant step of the received sample, or NOTHING
    queued: np.ndarray  # (L, n, SETPOINT): setpoints on their way, by the step they act at
    queued_valid: np.ndarray  # (L, n) bool


def lost_masks(ticks: int, n: int, loss: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Which samples (down) and setpoints (up) are lost, (ticks, n) each, from the seed."""
    draws = np.random.default_rng(seed).random((2, ticks, n))
    return draws[0] < loss, draws[1] < loss


def make_link(delay_steps: np.ndarray, lost_down: np.ndarray, lost_up: np.ndarray,
              predict: bool) -> SimLink:
    """A link for n vehicles (arrays of a team, or a batch's concatenation)."""
    n = delay_steps.shape[0]
    depth = int(delay_steps.max(initial=0)) + 1
    active = bool(delay_steps.any() or lost_down.any() or lost_up.any())
    return SimLink(active, predict, np.ascontiguousarray(delay_steps, dtype=np.int64),
                   np.ascontiguousarray(lost_down), np.ascontiguousarray(lost_up),
                   np.zeros((depth, n, SAMPLE)), np.zeros((n, SAMPLE)),
                   np.full(n, NOTHING, dtype=np.int64), np.zeros((depth, n, SETPOINT)),
                   np.zeros((depth, n), dtype=np.bool_))


@njit(cache=True)
def record(link, step, p, v, rot, w, thrust_n, mass_kg, drag_per_s, g):
    """Keep the true state of plant step `step` and its measured acceleration T R e3 / m - k v
    - g e3, k the linear drag (at step 0 it fills the whole history: the vehicles hovered there
    before t = 0)."""
    depth = link.history.shape[0]
    first, last = (0, depth) if step == 0 else (step % depth, step % depth + 1)
    for slot in range(first, last):
        h = link.history[slot]
        for i in range(p.shape[0]):
            for k in range(3):
                h[i, k] = p[i, k]
                h[i, 3 + k] = v[i, k]
                h[i, 15 + k] = w[i, k]
                h[i, 18 + k] = thrust_n[i] * rot[i, k, 2] / mass_kg[i] - (g if k == 2 else 0.0)
                if drag_per_s[i] > 0.0:
                    h[i, 18 + k] -= drag_per_s[i] * v[i, k]
                for c in range(3):
                    h[i, 6 + 3 * k + c] = rot[i, k, c]


@njit(cache=True)
def receive(link, step, tick):
    """The law's view at the tick of plant step `step` (tick number `tick`): each vehicle's
    sample of step - d, unless lost; then, with prediction on, carried to step + d.
    Returns (p, v, R, w, a)."""
    n = link.delay_steps.shape[0]
    depth = link.history.shape[0]
    for i in range(n):
        d = link.delay_steps[i]
        if not link.lost_down[tick, i] or link.taken_step[i] == NOTHING:
            slot = max(step - d, 0) % depth  # before t = 0: the initial hover, in slot 0
            for k in range(SAMPLE):
                link.received[i, k] = link.history[slot, i, k]
            link.taken_step[i] = step - d
    p = np.empty((n, 3))
    v = np.empty((n, 3))
    rot = np.empty((n, 3, 3))
    w = np.empty((n, 3))
    acc = np.empty((n, 3))
    for i in range(n):
        for k in range(3):
            p[i, k] = link.received[i, k]
            v[i, k] = link.received[i, 3 + k]
            w[i, k] = link.received[i, 15 + k]
            acc[i, k] = link.received[i, 18 + k]
            for c in range(3):
                rot[i, k, c] = link.received[i, 6 + 3 * k + c]
    return p, v, rot, w, acc


@njit(cache=True)
def predict_to_act(p, v, rot, w, acc, link, step, dt_s):
    """Carry each received sample forward to the step its setpoint will act at (in place)."""
    for i in range(p.shape[0]):
        h = (step + link.delay_steps[i] - link.taken_step[i]) * dt_s
        h = min(max(h, 0.0), MAX_HORIZON_S)
        for k in range(3):
            p[i, k] += v[i, k] * h + 0.5 * acc[i, k] * h * h
            v[i, k] += acc[i, k] * h
        # R exp([w]x h) by Rodrigues' formula
        px, py, pz = w[i, 0] * h, w[i, 1] * h, w[i, 2] * h
        angle = np.sqrt(px * px + py * py + pz * pz)
        if angle < 1e-9:
            s, c = 1.0, 0.5
        else:
            s, c = np.sin(angle) / angle, (1.0 - np.cos(angle)) / (angle * angle)
        kx = np.array([[0.0, -pz, py], [pz, 0.0, -px], [-py, px, 0.0]])
        step_m = np.eye(3) + s * kx + c * (kx @ kx)
        rot[i] = rot[i] @ step_m


@njit(cache=True)
def send(link, step, tick, thrust_n, rate_cmd, torque, rc):
    """Queue each vehicle's setpoint of this tick to act d steps later (unless lost)."""
    depth = link.queued.shape[0]
    for i in range(thrust_n.shape[0]):
        if link.lost_up[tick, i]:
            continue
        slot = (step + link.delay_steps[i]) % depth
        q = link.queued[slot, i]
        q[0] = thrust_n[i]
        for k in range(3):
            q[1 + k] = rate_cmd[i, k]
            q[4 + k] = torque[i, k]
            for c in range(3):
                q[7 + 3 * k + c] = rc[i, k, c]
        link.queued_valid[slot, i] = True


@njit(cache=True)
def deliver(link, step, thrust_hold, rate_cmd, torque_hold, rc_hold):
    """The setpoints that act from this step on replace the held ones."""
    slot = step % link.queued.shape[0]
    for i in range(thrust_hold.shape[0]):
        if link.queued_valid[slot, i]:
            q = link.queued[slot, i]
            thrust_hold[i] = q[0]
            for k in range(3):
                rate_cmd[i, k] = q[1 + k]
                torque_hold[i, k] = q[4 + k]
                for c in range(3):
                    rc_hold[i, k, c] = q[7 + 3 * k + c]
            link.queued_valid[slot, i] = False
