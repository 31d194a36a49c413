"""The cascade criterion's model of PX4's roll/pitch rate loop against the recorded doublets.

    python -m benchmarks.calibration.fit_rate_response [--no-write]

The criterion (gcs/control/cascade.py) models the autopilot's rate loop as a second order plus
a dead time, G(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-s T}. This script fits that model in
least squares to the four recorded PX4 v1.16.0 SIH roll and pitch doublets over their whole
traces (ATTITUDE_QUATERNION rates on the vehicle's sample times, tests/data/sitl/px4/
rate_steps.tlog.gz; the doublets' edges as sent), and sets beside it, on the same traces:
``PX4_RESPONSE`` (what the criterion uses), the model read off the roll step's peak overshoot
and t63 alone (zeta 0.30, wn 14.7 rad/s, 4 ms: the criterion's model before this fit), and the
px4 personality's own rate loop (its plant kernel flying the same doublets). Residuals are rms
over every sample of the four traces [rad/s]; the gain at 6 and 13 rad/s is the model's
|G(j w)|, the frequencies where the position loop's crossover and the old model's resonance sit.
Writes the section "## PX4 rate loop: the criterion's model against the recorded doublets" of
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.optimize import least_squares

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.calibration.fit_emulator import kernel_doublets, recorded_rates  # noqa: E402
from benchmarks.docsection import publish  # noqa: E402
from gcs.control.cascade import PX4_RESPONSE  # noqa: E402
from vehicle_emulator.calibration import replay as rp  # noqa: E402
from vehicle_emulator.config.personality import PERSONALITIES  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]

DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## PX4 rate loop: the criterion's model against the recorded doublets"
PEAK_READ = (0.30, 14.7, 0.004)  # zeta, wn [rad/s], T [s] from the roll step's 37 % peak
LEAD_S = 0.1  # each trace starts this long before the doublet's first edge
TAIL_S = 0.5  # and ends this long after its last


def traces(rec: rp.Recording) -> list[tuple[rp.Doublet, np.ndarray, np.ndarray]]:
    """Per roll/pitch doublet: (doublet, time from its first edge [s], measured rate [rad/s])."""
    t_rec, rates = recorded_rates(rec)
    out = []
    for d in rec.doublets:
        if d.axis == 2:
            continue
        keep = (t_rec >= d.edges_s[0] - LEAD_S) & (t_rec <= d.edges_s[2] + TAIL_S)
        out.append((d, t_rec[keep] - d.edges_s[0], rates[keep, d.axis]))
    return out


def model_response(zeta: float, wn: float, dead_s: float, gain: float, d: rp.Doublet,
                   t_s: np.ndarray) -> np.ndarray:
    """gain G(s) answering the doublet's commanded rate, at times t_s from its first edge."""
    ts = np.arange(-LEAD_S, t_s[-1] + 0.01, 0.001)
    edges = np.array(d.edges_s) - d.edges_s[0]
    cmd = np.select([ts < 0.0, ts < edges[1], ts < edges[2]], [0.0, d.amp_radps, -d.amp_radps],
                    0.0)
    _, y, _ = signal.lsim(signal.lti([gain * wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), cmd,
                          ts - ts[0])
    return np.interp(t_s - dead_s, ts, y)


def residual(params, data) -> np.ndarray:
    zeta, wn, dead_s, gain = params
    return np.concatenate([model_response(zeta, wn, dead_s, gain, d, t) - y for d, t, y in data])


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def noise_floor(data) -> float:
    """rms of the recorded rate before each doublet's first edge (commanded rate 0)."""
    return rms(np.concatenate([y[t_s < 0.0] - y[t_s < 0.0].mean() for _, t_s, y in data]))


def gain_at(zeta: float, wn: float, w_radps: float) -> float:
    s = 1j * w_radps
    return float(abs(wn * wn / (s * s + 2.0 * zeta * wn * s + wn * wn)))


def personality_rms(rec: rp.Recording, data) -> float:
    """The px4 personality's plant kernel flying the recorded doublets, against the recording."""
    flown = {}
    for axis in (0, 1):
        for edge0, t, ys in kernel_doublets(rec, [PERSONALITIES["px4"]], axis):
            flown[edge0] = (t, ys[0])
    return rms(np.concatenate([np.interp(t_s, *flown[d.edges_s[0]]) - y for d, t_s, y in data]))


def section() -> str:
    rec = rp.load_recording("px4")
    data = traces(rec)
    fit = least_squares(residual, [0.5, 15.0, 0.01, 1.0], args=(data,),
                        bounds=([0.05, 3.0, 0.0, 0.5], [2.0, 80.0, 0.08, 1.5]))
    zeta, wn, dead_s, gain = fit.x
    p = PX4_RESPONSE
    rows = [
        ("least-squares fit (gain free)", zeta, wn, dead_s, gain, rms(fit.fun)),
        ("`PX4_RESPONSE` (the criterion's)", p.rate_damping, p.rate_natural_radps,
         p.rate_dead_time_s, 1.0, rms(residual([p.rate_damping, p.rate_natural_radps,
                                                 p.rate_dead_time_s, 1.0], data))),
        ("read off the roll step's peak (before)", *PEAK_READ, 1.0,
         rms(residual([*PEAK_READ, 1.0], data))),
    ]
    lines = [
        HEADING,
        "",
        "`python -m benchmarks.calibration.fit_rate_response` (the script's docstring says what is "
        f"compared): {len(data)} recorded PX4 v1.16.0 SIH roll and pitch doublets (+-0.5 rad/s), "
        "second order + dead time per model; rms of (model - recorded rate) over every sample "
        "[rad/s].",
        "",
        "| model | zeta | wn [rad/s] | dead time [ms] | gain | rms residual | model's gain at 6 / 13 rad/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, z, w, t, g, r in rows:
        lines.append(f"| {label} | {z:.2f} | {w:.1f} | {1e3 * t:.1f} | {g:.2f} | {r:.3f} | "
                     f"{gain_at(z, w, 6.0):.2f} / {gain_at(z, w, 13.0):.2f} |")
    lines += [
        f"| px4 personality (its rate loop flying the same doublets) | | | | | "
        f"{personality_rms(rec, data):.3f} | |",
        "",
        f"The recorded rate carries SIH's gyro noise ({noise_floor(data):.3f} rad/s rms in the "
        f"{1e3 * LEAD_S:.0f} ms before each doublet, where the command is 0), the floor of any "
        "model's residual. A peak read "
        "off one noisy step overstates the overshoot and with it the resonance: a model with a "
        "1.7-fold gain at 13 rad/s (the whole-trace fit: 0.89) fits the traces twice as "
        "badly, and made the criterion refuse position gains on PX4 that fly well.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-write", action="store_true", help="print, do not edit the doc")
    args = ap.parse_args(argv)
    publish(DOC, HEADING, section(), write=not args.no_write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
