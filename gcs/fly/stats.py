"""Tick timing and per-vehicle telemetry-age statistics of a flight (for report.json). Pure.

Telemetry ages are true ages: how long before the tick the vehicle took the sample, from its own
time_boot_ms (gcs.link.clock), the link's transport and queueing included; receive ages (time
since the sample arrived) are kept beside them.

A tick is *late* when it starts more than `late_threshold_s(period)` after its deadline: a fifth
of the period, but at least 1.5 ms (asyncio wakes up on a millisecond timer, so sub-millisecond
thresholds would measure the timer, not the design). Lateness, compute time and telemetry ages are
stored in preallocated, growing arrays (no per-tick allocation beyond amortised growth).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from gcs.control.predict import AuditFigures
from gcs.link.clock import ClockEstimate

MIN_LATE_THRESHOLD_S = 1.5e-3


def late_threshold_s(period_s: float) -> float:
    return max(MIN_LATE_THRESHOLD_S, 0.2 * period_s)


def log_due(k: int, k0: int, every: int, next_k: int) -> tuple[bool, int]:
    """Whether tick ``k`` (formation ticks counted from ``k0``) takes the flight log's sample,
    and the tick the next one is due at. A sample is due at every ``every``-th tick; one whose
    tick was skipped (a late loop jumps to the newest deadline) is taken at the first tick after
    it, at its own time (a stall shorter than half the log period leaves no hole in the
    report's grid; a longer one shows as the gap it was).
    ``next_k``: what the previous call returned (``k0`` at first)."""
    if k < next_k:
        return False, next_k
    return True, k0 + every * ((k - k0) // every + 1)


class _Grow:
    """Append-only float array of fixed row width."""

    def __init__(self, width: int, capacity: int = 4096) -> None:
        self._a = np.empty((capacity, width))
        self.n = 0

    def append(self, row: np.ndarray | float) -> None:
        if self.n == self._a.shape[0]:
            self._a = np.concatenate((self._a, np.empty_like(self._a)))
        self._a[self.n] = row
        self.n += 1

    @property
    def data(self) -> np.ndarray:
        return self._a[: self.n]


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else float("nan")


#: A gap between two ticks at least this long is a stall of the ground station [s]: its
#: vehicles flew that long on the setpoints they had.
STALL_S = 0.05
#: Stalls listed in the report (the count covers them all).
STALLS_LISTED = 50


class TickStats:
    """Lateness [s] and compute time [s] of every tick, skipped ticks, late count, and the
    stalls (STALL_S or longer without a tick) with their time and length."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.period_s = 1.0 / rate_hz
        self.threshold_s = late_threshold_s(self.period_s)
        self._late = _Grow(1)
        self._compute = _Grow(1)
        self.skipped = 0
        self.stalls: list[tuple[float, float]] = []
        self.stall_count = 0

    def skip(self, periods: int, t_s: float) -> float | None:
        """Count `periods` deadlines jumped over at time `t_s`; the stall's length [s] if the
        ground station stopped for STALL_S or longer, else None."""
        self.skipped += periods
        gap_s = (periods + 1) * self.period_s
        if gap_s < STALL_S:
            return None
        self.stall_count += 1
        if len(self.stalls) < STALLS_LISTED:
            self.stalls.append((t_s, gap_s))
        return gap_s

    def record(self, lateness_s: float, compute_s: float) -> None:
        self._late.append(lateness_s)
        self._compute.append(compute_s)

    @property
    def ticks(self) -> int:
        return self._late.n

    def late_fraction(self) -> float:
        """Of every deadline, the ticks that started late and the ticks skipped (a deadline the
        loop jumped over is a tick not run on time, not one to leave out)."""
        late = self._late.data[:, 0]
        deadlines = late.size + self.skipped
        if not deadlines:
            return 0.0
        return float((late > self.threshold_s).sum() + self.skipped) / deadlines

    def report(self) -> dict[str, Any]:
        late = self._late.data[:, 0]
        comp = self._compute.data[:, 0]
        return {
            "rate_hz": self.rate_hz,
            "late_pct": 100.0 * self.late_fraction(),
            "lateness_p99_ms": 1e3 * _pct(late, 99),
            "lateness_p50_ms": 1e3 * _pct(late, 50),
            "lateness_max_ms": 1e3 * float(late.max()) if late.size else None,
            "late_threshold_ms": 1e3 * self.threshold_s,
            "ticks": int(late.size),  # run; the skipped ones are late_pct's too
            "skipped_ticks": self.skipped,
            "stalls": self.stall_count,
            "stalls_at_s_ms": [[round(t, 3), round(1e3 * g, 1)] for t, g in self.stalls],
            "compute_p50_ms": 1e3 * _pct(comp, 50),
            "compute_p99_ms": 1e3 * _pct(comp, 99),
        }


class AgeStats:
    """Per vehicle, at each formation tick: the true age [s] of the data it used (taken how long
    ago, from the vehicle's own stamps), the time since it was received, and stale counters."""

    def __init__(self, n: int) -> None:
        self._age = _Grow(n)
        self._rx = _Grow(n)
        self.stale_own = np.zeros(n, dtype=np.int64)
        self.stale_neighbour = np.zeros(n, dtype=np.int64)

    def record(self, age_s: np.ndarray, rx_age_s: np.ndarray, fresh: np.ndarray,
               stale_neighbours: np.ndarray) -> None:
        self._age.append(age_s)
        self._rx.append(rx_age_s)
        self.stale_own += ~fresh
        self.stale_neighbour += stale_neighbours

    def percentiles_ms(self, q: float, *, received: bool = False) -> np.ndarray:
        """(n,) the q-th percentile of the true ages (``received``: of the receive ages) [ms]."""
        a = (self._rx if received else self._age).data
        if not a.shape[0]:
            return np.full(a.shape[1], np.nan)
        finite = np.where(np.isfinite(a), a, np.nan)
        return 1e3 * np.nanpercentile(finite, q, axis=0)


def clock_report(est: ClockEstimate) -> dict[str, Any]:
    """The vehicle clock filter's view at the end: offset [s], drift [ppm], least one-way
    delay [ms] (half the least recent round trip), restarts, lasting delay rises."""
    return {"synced": est.synced, "offset_s": est.offset_s if est.synced else None,
            "drift_ppm": est.drift_ppm, "least_delay_ms": 1e3 * est.least_delay_s,
            "restarts": est.resets, "delay_rises": est.delay_rises}


def prediction_report(f: AuditFigures | None) -> dict[str, Any]:
    """The delay compensation of one vehicle (gcs.control.predict): its horizons [ms] and the error
    of its predicted states, beside the samples held without prediction, p50 / p99 / max
    (position [m], attitude [deg]); {"enabled": False} when fly.predict is off."""
    if f is None:
        return {"enabled": False}

    def dist(x: np.ndarray, scale: float = 1.0) -> dict[str, float | None]:
        if not x.size:
            return {"p50": None, "p99": None, "max": None}
        return {"p50": scale * _pct(x, 50), "p99": scale * _pct(x, 99),
                "max": scale * float(x.max())}

    deg = math.degrees(1.0)
    return {"enabled": True, "resolved": f.resolved, "horizon_ms": dist(f.horizon_s, 1e3),
            "position_m": dist(f.position_m), "position_held_m": dist(f.position_held_m),
            "attitude_deg": dist(f.attitude_rad, deg),
            "attitude_held_deg": dist(f.attitude_held_rad, deg)}


def round_trip_report(rtt_s: np.ndarray) -> dict[str, Any]:
    """TIMESYNC round trips of one link: count and p50 / p99 / max [ms] (None without any)."""
    if not rtt_s.size:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {"n": int(rtt_s.size), "p50_ms": 1e3 * _pct(rtt_s, 50),
            "p99_ms": 1e3 * _pct(rtt_s, 99), "max_ms": 1e3 * float(rtt_s.max())}


def link_report(
    vehicle_ids: Sequence[int],
    ages: AgeStats,
    setpoints_sent: Sequence[int],
    telemetry_received: Sequence[int],
    telemetry_lost: Sequence[int],
    extra: Sequence[dict[str, Any]] | None = None,
) -> dict[str, dict[str, Any]]:
    """The report's `link` object: per vehicle id, the schema's fields (docs/report.md)
    plus `extra[i]`."""
    p50, p99, top = ages.percentiles_ms(50), ages.percentiles_ms(99), ages.percentiles_ms(100)
    rx99 = ages.percentiles_ms(99, received=True)
    out: dict[str, dict[str, Any]] = {}
    for i, vid in enumerate(vehicle_ids):
        got, lost = int(telemetry_received[i]), int(telemetry_lost[i])
        entry: dict[str, Any] = {
            "setpoints_sent": int(setpoints_sent[i]),
            "telemetry_received": got,
            "telemetry_lost_pct": 100.0 * lost / (got + lost) if got + lost else 0.0,
            "telemetry_age_p50_ms": float(p50[i]),
            "telemetry_age_p99_ms": float(p99[i]),
            "telemetry_age_max_ms": float(top[i]),
            "receive_age_p99_ms": float(rx99[i]),
            "stale_own_ticks": int(ages.stale_own[i]),
            "stale_neighbour_ticks": int(ages.stale_neighbour[i]),
        }
        if extra is not None:
            entry.update(extra[i])
        out[str(int(vid))] = entry
    return out
