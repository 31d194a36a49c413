"""Delay compensation: the team's telemetry predicted to the time its setpoints act. Pure.

A setpoint computed at tick time t reaches vehicle i one uplink delay later and acts from then
on, while the samples it is computed from were taken earlier still: the position at t_p,i, the
attitude at t_a,i (the vehicle's own stamps on the ground station's clock, gcs.link.clock). The
law therefore reads every vehicle's state predicted to one act time

    T = t + d_up,    d_up = the median over the team of each link's least one-way delay

(half its least recent TIMESYNC round trip; 0 without replies), over the horizons
h_p = T - t_p,i and h_a = T - t_a,i, each clamped to [0, MAX_HORIZON_S], with the vehicle's
kinematics and its latest acceleration and body rates held:

    p(T) = p + v h_p + a h_p^2 / 2,    v(T) = v + a h_p,    R(T) = R exp([omega]x h_a)

(a: the measured specific force rotated to the world, minus g e3, as the law reads it; omega:
body FLU rates; exp by Rodrigues' formula). One act time for the whole team, not one per
vehicle: vehicle i's law reads its neighbours' positions relative to its own, and predicting all
of them to the same instant keeps those differences right under the formation's common motion;
each own state is then early or late only by the spread of the uplink delays (a few ms).

`PredictionAudit` measures the predictor in flight: each prediction is compared with the sample
the vehicle later reports for that instant (the first one taken at or after T, carried back to
T by its own velocity or rates over at most `RESOLVE_WITHIN_S`), beside the error of the sample
the law would have read without prediction. Against the `nominal` emulator, whose telemetry is
its true state, that is the error against the truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from gcs.control.law import TeamMeasurement

#: Longest prediction [s]: data older than this is the delay rule's (fly.max_data_age_s 0.3 s by
#: default), and a held acceleration is no model of a longer future.
MAX_HORIZON_S = 0.3
#: A reported sample taken this long after a prediction's act time still resolves it [s].
RESOLVE_WITHIN_S = 0.02
#: Predictions awaiting their sample, per vehicle (MAX_HORIZON_S at 100 Hz needs 30).
AUDIT_SLOTS = 64


def rotation_step(rotation: np.ndarray, omega_radps: np.ndarray,
                  horizon_s: np.ndarray) -> np.ndarray:
    """R exp([omega]x h) for (n, 3, 3) rotations, (n, 3) body rates, (n,) horizons."""
    phi = omega_radps * horizon_s[:, None]
    angle = np.sqrt((phi * phi).sum(axis=1))
    small = angle < 1e-9
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 1.0, np.sin(safe) / safe)  # sin(x)/x and (1 - cos x)/x^2 near 0
    c = np.where(small, 0.5, (1.0 - np.cos(safe)) / (safe * safe))
    k = np.zeros_like(rotation)
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = phi[:, 2], -phi[:, 1], phi[:, 0]
    step = np.eye(3)[None] + s[:, None, None] * k + c[:, None, None] * (k @ k)
    return rotation @ step


def horizons_s(act_time_s: float, taken_s: np.ndarray) -> np.ndarray:
    """act_time - taken, clamped to [0, MAX_HORIZON_S]; 0 where nothing was taken yet."""
    h = act_time_s - np.asarray(taken_s, dtype=float)
    return np.where(np.isfinite(h), np.clip(h, 0.0, MAX_HORIZON_S), 0.0)


def predict(m: TeamMeasurement, position_horizon_s: np.ndarray,
            attitude_horizon_s: np.ndarray) -> TeamMeasurement:
    """The team's state after the given horizons (n,) [s] (module docstring)."""
    h = position_horizon_s[:, None]
    a = m.acceleration_mps2
    return TeamMeasurement(m.position_m + m.velocity_mps * h + 0.5 * a * h * h,
                           m.velocity_mps + a * h, a,
                           rotation_step(m.rotation, m.omega_radps, attitude_horizon_s),
                           m.omega_radps)


def uplink_delay_s(least_delays_s: np.ndarray) -> float:
    """The team's uplink delay: the median of its links' least one-way delays (finite ones)."""
    d = np.asarray(least_delays_s, dtype=float)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else 0.0


def rotation_angle_rad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of a^T b for (..., 3, 3) rotations [rad], from |a - b|_F = 2 sqrt(2) sin(angle / 2)
    (accurate near 0, where the trace's arccos is not)."""
    d = np.sqrt(((a - b) ** 2).sum(axis=(-2, -1)))
    return 2.0 * np.arcsin(np.clip(d / (2.0 * np.sqrt(2.0)), 0.0, 1.0))


@njit(cache=True)
def _reached(pending: np.ndarray, act_s: np.ndarray, taken_s: np.ndarray, within_s: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`PredictionAudit._reached` in one pass over the (slots, n) pending predictions (no
    temporaries of that size: it runs every tick): clears the reached ones, returns those
    resolved as (slot, vehicle, back) in slot-major order."""
    slots, n = pending.shape
    out_slot = np.empty(slots * n, dtype=np.int64)
    out_veh = np.empty(slots * n, dtype=np.int64)
    out_back = np.empty(slots * n)
    m = 0
    for k in range(slots):
        for i in range(n):
            if pending[k, i]:
                back = taken_s[i] - act_s[k, i]
                if back >= 0.0:  # NaN compares false: not reached
                    pending[k, i] = False
                    if back <= within_s:
                        out_slot[m], out_veh[m], out_back[m] = k, i, back
                        m += 1
    return out_slot[:m], out_veh[:m], out_back[:m]


@dataclass(frozen=True, slots=True)
class AuditFigures:
    """Errors of one vehicle's predictions, and of the samples held without prediction."""

    resolved: int
    horizon_s: np.ndarray  # the position horizon of every recorded prediction [s]
    position_m: np.ndarray  # predicted position's error per resolved prediction [m]
    position_held_m: np.ndarray  # the held sample's
    attitude_rad: np.ndarray
    attitude_held_rad: np.ndarray


class PredictionAudit:
    """Predictions against what the vehicles later reported for their act times (module
    docstring). Record each tick's prediction with `record`, feed each tick's sample (the
    newest position and attitude with their taken times) to `observe`."""

    def __init__(self, n: int) -> None:
        self.n = n
        self._slot = 0
        shape = (AUDIT_SLOTS, n)
        self._t = np.full(shape, np.nan)  # act time of each pending prediction (GCS clock)
        self._pos_pending = np.zeros(shape, dtype=bool)
        self._att_pending = np.zeros(shape, dtype=bool)
        self._p = np.zeros((*shape, 3))  # predicted
        self._p0 = np.zeros((*shape, 3))  # held
        self._r = np.zeros((*shape, 3, 3))
        self._r0 = np.zeros((*shape, 3, 3))
        self._errors: list[list[np.ndarray]] = [[] for _ in range(4)]  # per kind: (vehicle, err)
        self._vehicles: list[list[np.ndarray]] = [[] for _ in range(4)]
        self._horizons: list[np.ndarray] = []
        self._joined: tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray] | None = None

    def record(self, act_time_s: float, predicted: TeamMeasurement, held: TeamMeasurement,
               position_horizon_s: np.ndarray) -> None:
        """One tick's prediction to `act_time_s` and the samples it started from."""
        self._horizons.append(np.array(position_horizon_s, dtype=float))
        self._joined = None
        k = self._slot % AUDIT_SLOTS
        self._slot += 1
        self._t[k] = act_time_s
        self._pos_pending[k] = self._att_pending[k] = True
        self._p[k], self._p0[k] = predicted.position_m, held.position_m
        self._r[k], self._r0[k] = predicted.rotation, held.rotation

    def observe(self, position_m: np.ndarray, velocity_mps: np.ndarray,
                position_taken_s: np.ndarray, rotation: np.ndarray, omega_radps: np.ndarray,
                attitude_taken_s: np.ndarray) -> None:
        """Resolve the pending predictions whose act time the newest samples reached."""
        # position: the sample carried back to the act time by its own velocity
        slot, veh, back = self._reached(self._pos_pending, position_taken_s)
        if veh.size:
            truth = position_m[veh] - velocity_mps[veh] * back[:, None]
            self._keep(0, veh, np.linalg.norm(self._p[slot, veh] - truth, axis=1))
            self._keep(1, veh, np.linalg.norm(self._p0[slot, veh] - truth, axis=1))
        # attitude: carried back by its own body rates
        slot, veh, back = self._reached(self._att_pending, attitude_taken_s)
        if veh.size:
            truth = rotation_step(rotation[veh], omega_radps[veh], -back)
            self._keep(2, veh, rotation_angle_rad(self._r[slot, veh], truth))
            self._keep(3, veh, rotation_angle_rad(self._r0[slot, veh], truth))

    def _reached(self, pending: np.ndarray, taken_s: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pending predictions (slot, vehicle) whose act time a sample taken at `taken_s`
        has reached, no longer pending, and of those the ones it resolves (taken at most
        RESOLVE_WITHIN_S later), with how much later (back, >= 0)."""
        return _reached(pending, self._t, np.ascontiguousarray(taken_s, dtype=np.float64),
                        RESOLVE_WITHIN_S)

    def _keep(self, kind: int, vehicles: np.ndarray, errors: np.ndarray) -> None:
        self._vehicles[kind].append(vehicles)
        self._errors[kind].append(errors)
        self._joined = None

    def figures(self, i: int) -> AuditFigures:
        """Vehicle index i's errors so far."""
        if self._joined is None:  # joined once for every vehicle's figures
            kinds = [(np.concatenate(v) if v else np.zeros(0, dtype=int),
                      np.concatenate(e) if e else np.zeros(0))
                     for v, e in zip(self._vehicles, self._errors, strict=True)]
            horizons = np.stack(self._horizons) if self._horizons else np.zeros((0, self.n))
            self._joined = (kinds, horizons)
        kinds, horizons = self._joined
        per_kind = [e[v == i] for v, e in kinds]
        return AuditFigures(int(per_kind[0].size), horizons[:, i], *per_kind)
