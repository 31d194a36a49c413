"""The law's velocity made consistent with the reported position: a complementary filter. Pure.

An autopilot's estimator reports position and velocity as two outputs that need not agree: on
PX4 v1.16 SIH the reported position moves, over 1-5 s, by 0.13-0.28 m/s (rms per axis) more or
less than the reported velocity says (`benchmarks/calibration/fit_velocity_consistency.py` on the
recorded formation flights; docs/gcs.md, "The law's velocity"). The law (21)-(23) damps the
velocity it is given and positions the vehicles on the positions it is given; an offset d
between the two holds each formation mode lambda at e = 2 d / (c_p lambda) from its slot, as if
the vehicle were pushed. So the law reads

    v_law = v + c,    c = the reported mismatch (p' - v) low-passed with time constant T

per vehicle: the reported velocity at frequencies above 1 / T, the reported position's
derivative below. Where the two agree (ArduPilot's EKF3, the nominal emulator) c stays ~0 and
the law is unchanged; the linearised loops of the cascade criterion are unchanged either way
(on consistent signals v_law = v).

The mismatch is measured between consecutive position samples the ground station read (the
vehicle's own stamps on the ground station's clock), by the trapezoid rule on the two velocities.
A pair further apart than MAX_GAP_S, or whose mismatch exceeds MAX_MISMATCH_MPS (an estimator
reset: the position jumped), updates nothing and is counted; c is bounded to MAX_CORRECTION_MPS
per axis, so a misbehaving estimator can shift the law's velocity by that much at most.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Two position samples further apart than this [s] measure no mismatch (a gap in the telemetry).
MAX_GAP_S = 0.25
#: A mismatch above this [m/s, any axis] is a position reset (a jump), not a rate: skipped.
MAX_MISMATCH_MPS = 5.0
#: The largest correction [m/s per axis] the filter applies.
MAX_CORRECTION_MPS = 0.5


class VelocityConsistency:
    """Per vehicle: the low-passed mismatch c between the reported position's rate and the
    reported velocity (module docstring). `time_constant_s` <= 0: off (c stays 0)."""

    def __init__(self, n: int, time_constant_s: float) -> None:
        self.time_constant_s = float(time_constant_s)
        self.correction_mps = np.zeros((n, 3))
        self.resets = np.zeros(n, dtype=np.int64)  # pairs skipped as a jump
        self.clamped = np.zeros(n, dtype=np.int64)  # updates that hit MAX_CORRECTION_MPS
        self._t = np.full(n, -math.inf)
        self._p = np.full((n, 3), np.nan)
        self._v = np.full((n, 3), np.nan)
        self._square_sum = np.zeros(n)
        self._updates = 0

    @property
    def on(self) -> bool:
        return self.time_constant_s > 0.0

    def update(self, position_m: np.ndarray, velocity_mps: np.ndarray, taken_s: np.ndarray,
               finite: np.ndarray) -> None:
        """Feed the team's latest samples (n, 3) taken at `taken_s` (n,); rows not `finite` or
        not newer than the last one fed are ignored."""
        if not self.on:
            return
        new = finite & np.isfinite(taken_s) & (taken_s > self._t)
        if not new.any():
            return
        dt = taken_s - self._t
        pair = new & (dt <= MAX_GAP_S) & np.isfinite(self._p).all(axis=1)
        if pair.any():
            safe_dt = np.where(pair, dt, 1.0)[:, None]
            mismatch = ((position_m - self._p) / safe_dt
                        - 0.5 * (velocity_mps + self._v))
            with np.errstate(invalid="ignore"):
                jump = pair & (np.abs(mismatch) > MAX_MISMATCH_MPS).any(axis=1)
            self.resets += jump
            use = pair & ~jump
            gain = np.where(use, -np.expm1(-np.where(use, dt, 0.0) / self.time_constant_s), 0.0)
            step = np.where(use[:, None], mismatch - self.correction_mps, 0.0)
            c = self.correction_mps + gain[:, None] * step
            over = use & (np.abs(c) > MAX_CORRECTION_MPS).any(axis=1)
            self.clamped += over
            self.correction_mps = np.clip(c, -MAX_CORRECTION_MPS, MAX_CORRECTION_MPS)
        self._t = np.where(new, taken_s, self._t)
        self._p = np.where(new[:, None], position_m, self._p)
        self._v = np.where(new[:, None], velocity_mps, self._v)

    def update_figures(self) -> None:
        """Once per law tick: the correction's running square sum (the report's RMS)."""
        if self.on:
            self._square_sum += (self.correction_mps ** 2).sum(axis=1)
            self._updates += 1

    def report(self, i: int) -> dict[str, Any] | None:
        """Vehicle i's figures for the report: the time constant, the correction's RMS over the
        law's ticks and its last value [m/s, ENU], and the pairs skipped as position jumps or
        clamped; None when off."""
        if not self.on:
            return None
        rms = math.sqrt(self._square_sum[i] / self._updates) if self._updates else None
        return {"time_constant_s": self.time_constant_s,
                "correction_rms_mps": None if rms is None else round(rms, 4),
                "correction_last_enu_mps": [round(float(x), 4) for x in self.correction_mps[i]],
                "position_jumps": int(self.resets[i]), "clamped": int(self.clamped[i])}

    def velocity(self, velocity_mps: np.ndarray) -> np.ndarray:
        """The law's velocity: the reported one plus the correction."""
        return velocity_mps + self.correction_mps if self.on else velocity_mps
