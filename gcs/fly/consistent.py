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
A pair further apart than MAX_GAP_S, or whose mismatch exceeds VELOCITY_JUMP_MPS (an estimator
reset: the position jumped), updates nothing and is counted; c is bounded to VELOCITY_MAX_MPS
per axis (both bounds in gcs/control/consistency.py, which gcs sim's copy of this filter reads
too), so a misbehaving estimator can shift the law's velocity by that much at most.

The law's acceleration (its u', u'' of docs/control-law.md) is made consistent with that velocity
by the same filter one derivative down (`AccelerationConsistency`): gcs fly turns the
accelerometer's specific force to the world by the reported attitude, so an attitude estimate off
by e reads as a horizontal acceleration g e the vehicle does not have (PX4's EKF2 tilt and
heading errors last seconds); the law's velocity, which follows the reported position at low
frequency, has none of it. So

    a_law = a + c_a,   c_a = (v_law' - a) low-passed with time constant T_a

the accelerometer's reading above 1 / T_a, the law velocity's rate below it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gcs.control.consistency import (
    ACCELERATION_JUMP_MPS2,
    ACCELERATION_MAX_MPS2,
    VELOCITY_JUMP_MPS,
    VELOCITY_MAX_MPS,
)

#: Two samples further apart than this [s] measure no mismatch (a gap in the telemetry).
MAX_GAP_S = 0.25


class Consistency:
    """Per vehicle: the low-passed mismatch c between the rate of a reported quantity x and the
    reported rate r that should be its derivative (module docstring). `time_constant_s` <= 0:
    off (c stays 0). Skips a pair whose mismatch exceeds `max_mismatch` (counted in `resets`),
    bounds c to `max_correction` per axis (counted in `clamped`)."""

    def __init__(self, n: int, time_constant_s: float, max_mismatch: float,
                 max_correction: float, unit: str) -> None:
        self.time_constant_s = float(time_constant_s)
        self.unit = unit  # of the rate, in the report's keys
        self.max_mismatch, self.max_correction = max_mismatch, max_correction
        self.correction = np.zeros((n, 3))
        self.resets = np.zeros(n, dtype=np.int64)  # pairs skipped as a jump
        self.clamped = np.zeros(n, dtype=np.int64)  # updates that hit max_correction
        self._t = np.full(n, -math.inf)
        self._x = np.full((n, 3), np.nan)
        self._r = np.full((n, 3), np.nan)
        self._square_sum = np.zeros(n)
        self._updates = 0

    @property
    def on(self) -> bool:
        return self.time_constant_s > 0.0

    def update(self, x: np.ndarray, rate: np.ndarray, taken_s: np.ndarray,
               finite: np.ndarray) -> None:
        """Feed the team's latest samples (n, 3) taken at `taken_s` (n,); rows not `finite` or
        not newer than the last one fed are ignored."""
        if not self.on:
            return
        new = finite & np.isfinite(taken_s) & (taken_s > self._t)
        new &= np.isfinite(rate).all(axis=1)
        if not new.any():
            return
        with np.errstate(invalid="ignore"):  # -inf - -inf where nothing was taken yet
            dt = taken_s - self._t
        pair = new & (dt <= MAX_GAP_S) & np.isfinite(self._x).all(axis=1)
        if pair.any():
            safe_dt = np.where(pair, dt, 1.0)[:, None]
            mismatch = (x - self._x) / safe_dt - 0.5 * (rate + self._r)
            with np.errstate(invalid="ignore"):
                jump = pair & (np.abs(mismatch) > self.max_mismatch).any(axis=1)
            self.resets += jump
            use = pair & ~jump
            gain = np.where(use, -np.expm1(-np.where(use, dt, 0.0) / self.time_constant_s), 0.0)
            step = np.where(use[:, None], mismatch - self.correction, 0.0)
            c = self.correction + gain[:, None] * step
            over = use & (np.abs(c) > self.max_correction).any(axis=1)
            self.clamped += over
            self.correction = np.clip(c, -self.max_correction, self.max_correction)
        self._t = np.where(new, taken_s, self._t)
        self._x = np.where(new[:, None], x, self._x)
        self._r = np.where(new[:, None], rate, self._r)

    def update_figures(self) -> None:
        """Once per law tick: the correction's running square sum (the report's RMS)."""
        if self.on:
            self._square_sum += (self.correction ** 2).sum(axis=1)
            self._updates += 1

    def report(self, i: int) -> dict[str, Any] | None:
        """Vehicle i's figures for the report: the time constant, the correction's RMS over the
        law's ticks and its last value (ENU), and the pairs skipped as jumps or clamped; None
        when off."""
        if not self.on:
            return None
        rms = math.sqrt(self._square_sum[i] / self._updates) if self._updates else None
        return {"time_constant_s": self.time_constant_s,
                f"correction_rms_{self.unit}": None if rms is None else round(rms, 4),
                f"correction_last_enu_{self.unit}": [round(float(x), 4)
                                                      for x in self.correction[i]],
                "jumps": int(self.resets[i]), "clamped": int(self.clamped[i])}

    def corrected(self, rate: np.ndarray) -> np.ndarray:
        """The law's rate: the reported one plus the correction."""
        return rate + self.correction if self.on else rate


class VelocityConsistency(Consistency):
    """The law's velocity: the reported position's rate below 1 / T, the reported velocity
    above (fly.velocity_from_position_s)."""

    def __init__(self, n: int, time_constant_s: float) -> None:
        super().__init__(n, time_constant_s, VELOCITY_JUMP_MPS, VELOCITY_MAX_MPS, "mps")

    @property
    def correction_mps(self) -> np.ndarray:
        return self.correction

    def velocity(self, velocity_mps: np.ndarray) -> np.ndarray:
        """The law's velocity: the reported one plus the correction."""
        return self.corrected(velocity_mps)


class AccelerationConsistency(Consistency):
    """The law's acceleration: the law velocity's rate below 1 / T_a, the accelerometer's
    reading (turned by the reported attitude) above (fly.acceleration_from_velocity_s)."""

    def __init__(self, n: int, time_constant_s: float) -> None:
        super().__init__(n, time_constant_s, ACCELERATION_JUMP_MPS2,
                         ACCELERATION_MAX_MPS2, "mps2")
