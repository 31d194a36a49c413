"""The recorded experiments' figures (the data's README, "Signal definitions"), computed the same
way from recorded or replayed telemetry: rate-step delays and peaks, hover noise, thrust steps.

Inputs are plain arrays on one clock (seconds): sample times and values. Pure numpy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "LEVELS",
    "euler_from_quaternions",
    "fopdt_fit",
    "hover_std",
    "latency_above_envelope_ms",
    "step_response",
    "thrust_edge",
]

LEVELS = (0.1, 0.632, 0.9)
PEAK_AFTER_NEXT_EDGE_S = 0.15


def _crossing_ms(t: np.ndarray, y: np.ndarray, t0: float, t1: float, start: float,
                 change: float, level: float) -> float | None:
    """Time [ms] from t0 to the first sample in (t0, t1) at or beyond start + level * change."""
    m = (t > t0) & (t < t1)
    target = start + level * change
    hit = (y[m] >= target) if change > 0 else (y[m] <= target)
    if not hit.any():
        return None
    return float((t[m][np.argmax(hit)] - t0) * 1e3)


def step_response(t: np.ndarray, y: np.ndarray, edges_s: Sequence[float], amp: float) -> dict:
    """One doublet (0 -> +amp at edges_s[0], -> -amp at edges_s[1], -> 0 at edges_s[2]) of the
    measured rate y at sample times t: t10/t63/t90 [ms] from each edge's send time to the first
    sample at/beyond that fraction of the commanded change, the peak (extreme from the edge to
    0.15 s after the next edge) and the overshoot (peak - amp) / amp, for the step up and the
    reversal."""
    e0, e1, e2 = edges_s
    up = {f"t{round(lv * 100)}_ms": _crossing_ms(t, y, e0, e1, 0.0, amp, lv) for lv in LEVELS}
    m = (t > e0) & (t < e1 + PEAK_AFTER_NEXT_EDGE_S)
    up["peak"] = float(y[m].max()) if amp > 0 else float(y[m].min())
    up["overshoot_pct"] = 100.0 * (up["peak"] - amp) / amp
    rev = {
        f"t{round(lv * 100)}_ms": _crossing_ms(t, y, e1, e2, amp, -2.0 * amp, lv) for lv in LEVELS
    }
    m = (t > e1) & (t < e2 + PEAK_AFTER_NEXT_EDGE_S)
    rev["peak"] = float(y[m].min()) if amp > 0 else float(y[m].max())
    return {"up": up, "reversal": rev}


def hover_std(t: np.ndarray, y: np.ndarray, window_s: tuple[float, float],
              detrend: bool = False) -> float:
    """Standard deviation of y over the window (sample times), optionally about a fitted line."""
    m = (t >= window_s[0]) & (t < window_s[1])
    v = y[m]
    if detrend:
        v = v - np.polyval(np.polyfit(t[m], v, 1), t[m])
    return float(np.std(v))


def euler_from_quaternions(q: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw [rad] (n, 3) of quaternions (w, x, y, z) (n, 4); yaw unwrapped."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    return np.stack([roll, pitch, yaw], axis=1)


def thrust_edge(t: np.ndarray, up_mps2: np.ndarray, edge_s: float, du: float) -> dict:
    """One thrust edge: the gain [m/s^2 per unit thrust] from the mean upward specific force
    0.2-0.5 s after the edge minus the mean over the 0.3 s before, and the normalised response
    (t - edge [s], (up - baseline) / du) over -0.1..+0.3 s for the ensemble fit."""
    before = (t >= edge_s - 0.3) & (t < edge_s)
    after = (t >= edge_s + 0.2) & (t < edge_s + 0.5)
    base = float(np.mean(up_mps2[before]))
    win = (t >= edge_s - 0.1) & (t < edge_s + 0.3)
    return {
        "gain": (float(np.mean(up_mps2[after])) - base) / du,
        "t_rel_s": t[win] - edge_s,
        "norm": (up_mps2[win] - base) / du,
    }


def fopdt_fit(t_rel_s: np.ndarray, y: np.ndarray) -> dict:
    """Least squares y = K (1 - exp(-(t - d) / tau)) for t > d (0 before), over a grid of dead
    times d (1 ms) and time constants tau (2.5 ms), K in closed form: {dead_time_ms, tau_ms,
    gain, rms}."""
    best = None
    for d_ms in range(0, 41):
        d = d_ms * 1e-3
        for tau_ms in np.arange(2.5, 150.01, 2.5):
            shape = np.where(t_rel_s > d, 1.0 - np.exp(-(t_rel_s - d) / (tau_ms * 1e-3)), 0.0)
            ss = float(shape @ shape)
            if ss <= 0.0:
                continue
            k = float(shape @ y) / ss
            rms = float(np.sqrt(np.mean((y - k * shape) ** 2)))
            if best is None or rms < best["rms"]:
                best = {"dead_time_ms": float(d_ms), "tau_ms": float(tau_ms), "gain": k,
                        "rms": rms}
    assert best is not None
    return best


def latency_above_envelope_ms(streams: dict[str, tuple[np.ndarray, np.ndarray]],
                              window_s: float = 0.5) -> dict[str, float]:
    """Median latency above the envelope [ms] per stream (the README's "Signal definitions"):
    offset = receive time - sample time, envelope = the smallest offset of all the streams
    received in the next ``window_s``; ``streams``: name -> (receive times, sample times)."""
    rx = np.concatenate([r for r, _ in streams.values()])
    off = np.concatenate([r - t for r, t in streams.values()])
    order = np.argsort(rx)
    rx, off = rx[order], off[order]
    # forward-looking minimum over the window: the smallest offset in [t, t + window]
    env = np.empty_like(off)
    j = len(off) - 1
    for i in range(len(off) - 1, -1, -1):
        while j > i and rx[j] > rx[i] + window_s:
            j -= 1
        env[i] = off[i : j + 1].min()
    out = {}
    for name, (r, t) in streams.items():
        e = np.interp(r, rx, env)
        out[name] = float(np.median((r - t) - e) * 1e3)
    return out
