"""Pure error metrics of a formation flight and helpers to read a time series (no I/O, no clock).

Conventions (docs/report.md): "formation error" is max over all pairs i < j of
|p_i - p_j - theta_ij| with theta_ij = theta_i - theta_j; "velocity error" is max_i |v_i - v_r|;
"attitude error" is max_i tr(I - R_i^e). Vectors may be in any one frame, consistently. All
functions are vectorised over leading (sample) axes and propagate NaN (an unknown sample gives an
unknown error) unless their docstring says otherwise.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import numpy as np
from numba import njit


def relative_offsets(
    position_m: np.ndarray, offsets_m: np.ndarray, pairs: np.ndarray | None = None
) -> np.ndarray:
    """p_i - p_j - (theta_i - theta_j) for each pair (i, j) of vehicle indices.

    position_m (..., n, 3), offsets_m (n, 3), pairs (P, 2) of indices (default: all i < j in
    index order). Returns (..., P, 3) [m].
    """
    p = np.asarray(position_m, dtype=np.float64)
    theta = np.asarray(offsets_m, dtype=np.float64)
    _check_team(p, theta)
    if pairs is None:
        pairs = np.array(np.triu_indices(p.shape[-2], k=1)).T
    pairs = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    q = p - theta  # p_i - theta_i: identical for all i exactly when the formation is perfect
    return q[..., pairs[:, 0], :] - q[..., pairs[:, 1], :]


def formation_error(position_m: np.ndarray, offsets_m: np.ndarray) -> np.ndarray:
    """max over all pairs i < j of |p_i - p_j - theta_ij| [m].

    position_m (..., n, 3) (e.g. (k, n, 3)), offsets_m (n, 3). Returns shape (...) (e.g. (k,));
    0 for a single vehicle.
    """
    p = np.asarray(position_m, dtype=np.float64)
    theta = np.ascontiguousarray(offsets_m, dtype=np.float64)
    _check_team(p, theta)
    flat = np.ascontiguousarray(p.reshape((-1,) + p.shape[-2:]))
    return _formation_errors(flat, theta).reshape(p.shape[:-2])


@njit(cache=True)
def _formation_errors(position_m: np.ndarray, offsets_m: np.ndarray) -> np.ndarray:
    """`formation_error_m` of each sample of (k, n, 3): a flight's whole series without a
    (k, n^2 / 2, 3) array (240 vehicles, 3000 samples: 4 GB that way)."""
    out = np.empty(position_m.shape[0])
    for s in range(position_m.shape[0]):
        out[s] = formation_error_m(position_m[s], offsets_m)
    return out


@njit(cache=True)
def formation_error_m(position_m: np.ndarray, offsets_m: np.ndarray) -> float:
    """The formation error of one sample: max over all pairs of |p_i - p_j - (theta_i -
    theta_j)| [m] (gcs.metrics.formation_error), without an (n, n, 3) array. NaN if a position
    is NaN; 0 for one vehicle. O(n^2) arithmetic, nothing allocated."""
    n = position_m.shape[0]
    worst = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            d2 = 0.0
            for k in range(3):
                d = (position_m[i, k] - position_m[j, k]) - (offsets_m[i, k] - offsets_m[j, k])
                d2 += d * d
            if not d2 <= worst:  # larger, or NaN
                if d2 != d2:
                    return math.nan
                worst = d2
    if n == 1:
        for k in range(3):
            if position_m[0, k] != position_m[0, k]:
                return math.nan
    return math.sqrt(worst)


def velocity_error(velocity_mps: np.ndarray, reference_mps: np.ndarray) -> np.ndarray:
    """max over i of |v_i - v_r| [m/s]; velocity_mps (..., n, 3), reference_mps (..., 3)."""
    v = np.asarray(velocity_mps, dtype=np.float64)
    vr = np.asarray(reference_mps, dtype=np.float64)
    if v.ndim < 2 or v.shape[-1] != 3 or vr.shape != v.shape[:-2] + (3,):
        raise ValueError(
            f"velocity_error: expected velocity (..., n, 3) and reference (..., 3), "
            f"got {v.shape} and {vr.shape}"
        )
    return np.linalg.norm(v - vr[..., None, :], axis=-1).max(axis=-1)


def _check_team(p: np.ndarray, theta: np.ndarray) -> None:
    if p.ndim < 2 or p.shape[-1] != 3 or theta.shape != p.shape[-2:]:
        raise ValueError(
            f"expected position (..., n, 3) and offsets (n, 3), got {p.shape} and {theta.shape}"
        )


# --------------------------------------------------------------------------------------------------
# Reading a time series


def _tolerance_s(t_s: np.ndarray) -> float:
    """Half the median sample period (1e-9 s for a single sample): how far 'nearest' may be."""
    if t_s.size < 2:
        return 1e-9
    return 0.5 * float(np.median(np.diff(t_s)))


def nearest_index(t_s: np.ndarray, t: float) -> int:
    """Index of the sample nearest time ``t`` (ties go to the earlier sample).

    Raises ValueError if ``t`` lies outside the log by more than half a sample period.
    """
    ts = np.asarray(t_s, dtype=np.float64)
    tol = _tolerance_s(ts)
    if not ts[0] - tol <= t <= ts[-1] + tol:
        raise ValueError(f"t = {t} s is outside the log [{ts[0]}, {ts[-1]}] s")
    j = int(np.searchsorted(ts, t))
    if j == 0:
        return 0
    if j == ts.size:
        return ts.size - 1
    return j if ts[j] - t < t - ts[j - 1] else j - 1


def value_at(t_s: np.ndarray, values: np.ndarray, t: float) -> np.ndarray | float:
    """values[i] at the sample i nearest time t (values indexed by sample along axis 0)."""
    v = np.asarray(values)[nearest_index(t_s, t)]
    return float(v) if np.ndim(v) == 0 else v


def max_over_window(
    t_s: np.ndarray,
    values: np.ndarray,
    t_start: float | None = None,
    t_end: float | None = None,
) -> np.ndarray | float:
    """Maximum of ``values`` over the samples with t_start <= t <= t_end (default: whole log).

    Reduces axis 0 only, so (k, n) values give a per-vehicle maximum. NaN samples are ignored; an
    all-NaN window gives NaN. Raises ValueError if the window holds no sample.
    """
    return _reduce_window(np.nanmax, t_s, values, t_start, t_end)


def min_over_window(
    t_s: np.ndarray,
    values: np.ndarray,
    t_start: float | None = None,
    t_end: float | None = None,
) -> np.ndarray | float:
    """Minimum over a window; as max_over_window."""
    return _reduce_window(np.nanmin, t_s, values, t_start, t_end)


def _reduce_window(
    reduce: Callable[..., np.ndarray],
    t_s: np.ndarray,
    values: np.ndarray,
    t_start: float | None,
    t_end: float | None,
) -> np.ndarray | float:
    ts = np.asarray(t_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    lo = -math.inf if t_start is None else t_start
    hi = math.inf if t_end is None else t_end
    mask = (ts >= lo) & (ts <= hi)
    if not mask.any():
        raise ValueError(f"no sample in the window [{lo}, {hi}] s of the log [{ts[0]}, {ts[-1]}] s")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slice -> NaN, documented
        out = reduce(v[mask], axis=0)
    return float(out) if np.ndim(out) == 0 else out


def convergence_time(t_s: np.ndarray, values: np.ndarray, threshold: float) -> float | None:
    """Settling time: the first sample time from which ``values`` stays below ``threshold`` to
    the end of the log. None if the last sample is not below it (or is NaN); t_s[0] if always.

    values (k,) (or (k, ...): then every component must be below the threshold).
    """
    ts = np.asarray(t_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(ts.size, -1)
    below = np.all(v < threshold, axis=1)  # NaN compares False: an unknown sample is not below
    if not below[-1]:
        return None
    above = np.flatnonzero(~below)
    return float(ts[0] if above.size == 0 else ts[above[-1] + 1])


def grid_indices(t_s: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Resample onto the grid of integer multiples of ``period_s`` inside the log.

    Returns (grid_t_s, index). Grid times m * period_s run from the first to the last within half
    a log period of the log's ends, computed as m / (1 / period_s) when 1 / period_s is an integer
    (so 0.3 reads 0.3, not 0.30000000000000004). index is the nearest sample's, or -1 where no
    sample lies within half a log period (a gap). Log sample times are expected to be multiples of
    the log period (exactly, or up to a jitter below half of it).
    """
    ts = np.asarray(t_s, dtype=np.float64)
    if not period_s > 0:
        raise ValueError(f"period_s: expected > 0, got {period_s}")
    tol = min(_tolerance_s(ts), 0.5 * period_s)
    rate = 1.0 / period_s
    eps = 1e-9 * max(1.0, abs(ts[0]), abs(ts[-1])) * rate
    m0 = math.ceil((ts[0] - tol) / period_s - eps)  # a grid time within tol of an end is kept
    m1 = math.floor((ts[-1] + tol) / period_s + eps)
    m = np.arange(m0, m1 + 1, dtype=np.float64)
    grid = m / round(rate) if abs(rate - round(rate)) < 1e-9 else m * period_s
    j = np.clip(np.searchsorted(ts, grid), 1, max(ts.size - 1, 1))
    if ts.size == 1:
        idx = np.zeros(grid.size, dtype=np.intp)
    else:
        left, right = ts[j - 1], ts[j]
        idx = np.where(grid - left <= right - grid, j - 1, j).astype(np.intp)
    ok = np.abs(ts[idx] - grid) <= tol + 1e-12 * max(1.0, abs(ts[-1]))
    return grid, np.where(ok, idx, -1)
