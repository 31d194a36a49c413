"""Discrete-time stability of the attitude loops as flown over a link (docs/gcs.md). Pure.

The paper designs its attitude loop in continuous time. Over MAVLink the command is computed at a
fixed tick of period h from telemetry that is some ticks old, and held (zero-order hold) until the
next one. The criterion used by `gcs fly` linearises each body axis about R^e = I (eps ~ 2 theta,
omega^e ~ theta'). In actuators mode, torque (26): J theta'' = -(2 alpha_eps + 1/2) theta -
alpha_omega theta' (the 1/2 is -eps/(4 - tr(I - R^e)) at R^e = I). The Gamma rhohat feed-forward is
left out: it is exact when rhohat = J, and its error feeds back only through rhohat - J, which
actuators mode keeps small by adapting slowly (fly.actuators.alpha_rho; docs/control-law.md, "The
torque loop over a link"). (The rates and attitude modes, whose innermost loops the autopilot
closes, are checked by the cascade criterion of gcs/control/cascade.py over each autopilot's
measured response.)

It is discretised exactly (ZOH) with a pure measurement delay of d = 1 .. D ticks, D the ticks in
MAX_LOOP_DELAY_S (at least 2): the telemetry's age when the law reads it plus the vehicle's own
sampling. Over localhost the emulator's ATTITUDE_QUATERNION was 6.5 ms old at the median and 12.5
ms at p99 on a quiet machine, so 16 ms covers a quiet machine's p99 with a tick to spare at 250 Hz
(D = 4). (Beside two busy loops the p99 is 75-125 ms: the whole host stops for ~100 ms at a time,
which no choice of gains covers; docs/benchmarks.md, "Actuators mode beside two busy loops".) The
criterion: for every vehicle, every axis and every delay, the spectral radius rho of the discrete
closed loop is < 1, and its equivalent decay rate -ln(rho)/h is at least `min_decay_per_s` (default
1.5 /s; the paper's own continuous loop has a slowest attitude mode of about 2 (alpha_eps +
1/4)/alpha_omega = 2.0 /s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

MAX_LOOP_DELAY_S = 0.016
MIN_DELAY_TICKS = 2
MIN_DECAY_PER_S = 1.5


def delays_ticks(period_s: float, link_round_trip_s: float = 0.0) -> range:
    """The delays the criterion covers at tick period `period_s`: 1 .. D ticks, D the ticks
    MAX_LOOP_DELAY_S spans (at least MIN_DELAY_TICKS), plus those of a link's round trip
    (telemetry down, torque up) where the link itself is slow."""
    span_s = MAX_LOOP_DELAY_S + max(link_round_trip_s, 0.0)
    return range(1, max(MIN_DELAY_TICKS, math.ceil(span_s / period_s - 1e-9)) + 1)


@dataclass(frozen=True, slots=True)
class AxisMargin:
    """Worst case over the delays for one vehicle axis."""

    vehicle_id: int
    axis: str
    inertia_kgm2: float
    spectral_radius: float
    decay_per_s: float  # -ln(rho)/h; negative when unstable

    def ok(self, min_decay_per_s: float = MIN_DECAY_PER_S) -> bool:
        return self.spectral_radius < 1.0 and self.decay_per_s >= min_decay_per_s


def _delayed_loop_radius(phi: np.ndarray, gam: np.ndarray, gain: np.ndarray, delay: int) -> float:
    """Spectral radius of x_{k+1} = phi x_k - gam gain x_{k-delay} (augmented state)."""
    m = phi.shape[0]
    size = m * (delay + 1)
    a = np.zeros((size, size))
    a[:m, :m] = phi
    a[:m, m * delay : m * (delay + 1)] -= np.outer(gam, gain)
    for j in range(1, delay + 1):
        a[m * j : m * (j + 1), m * (j - 1) : m * j] = np.eye(m)
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def torque_loop_radius(
    alpha_eps: float, alpha_omega: float, inertia_kgm2: float, period_s: float, delay_ticks: int
) -> float:
    """rho of the linearised torque loop (26) of one axis, ZOH period h, measurement delay d."""
    h, j = period_s, inertia_kgm2
    phi = np.array([[1.0, h], [0.0, 1.0]])
    gam = np.array([h * h / (2.0 * j), h / j])
    gain = np.array([2.0 * alpha_eps + 0.5, alpha_omega])
    return _delayed_loop_radius(phi, gam, gain, delay_ticks)


def _decay(rho: float, period_s: float) -> float:
    return -math.log(rho) / period_s if rho > 0.0 else math.inf


def torque_margins(
    vehicle_ids: Sequence[int],
    inertias_kgm2: Sequence[Sequence[float]],
    alpha_eps: float,
    alpha_omega: float,
    tick_rate_hz: float,
    link_round_trip_s: float = 0.0,
) -> list[AxisMargin]:
    """Worst-case (over `delays_ticks`) margin of every vehicle axis in actuators mode.

    `inertias_kgm2` are the principal inertias (Jx, Jy, Jz) the check assumes: a lower bound is
    the safe choice, since the loop is stiffest for the smallest inertia.
    """
    h = 1.0 / tick_rate_hz
    out = []
    for vid, inertia in zip(vehicle_ids, inertias_kgm2, strict=True):
        for axis, j in zip("xyz", inertia, strict=True):
            rho = max(torque_loop_radius(alpha_eps, alpha_omega, j, h, d)
                      for d in delays_ticks(h, link_round_trip_s))
            out.append(AxisMargin(int(vid), axis, float(j), rho, _decay(rho, h)))
    return out


def describe_margins(margins: Sequence[AxisMargin],
                     min_decay_per_s: float = MIN_DECAY_PER_S) -> str:
    """One line per vehicle: worst axis, rho and decay rate, OK / NOT MET."""
    lines = []
    for vid in dict.fromkeys(m.vehicle_id for m in margins):
        worst = max((m for m in margins if m.vehicle_id == vid), key=lambda m: m.spectral_radius)
        lines.append(
            f"vehicle {vid}: worst axis {worst.axis} (J {worst.inertia_kgm2:g} kg m^2): rho "
            f"{worst.spectral_radius:.4f}, decay {worst.decay_per_s:.3g} /s: "
            f"{'OK' if worst.ok(min_decay_per_s) else 'NOT MET'}"
        )
    return "\n".join(lines)
