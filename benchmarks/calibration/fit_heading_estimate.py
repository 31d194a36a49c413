"""How far PX4's reported heading moves while its reported yaw rate says it does not: PX4 SIH
against the px4 personality.

For a window of w seconds the mismatch is the reported yaw's change minus the integral of the
reported yaw rate (ATTITUDE_QUATERNION); D(w) is its RMS over all windows (sliding, a quarter
window apart). Where D(w) grows faster than sqrt(w) the heading estimate's error is smooth (a
first-order Gauss-Markov error of time constant tau gives D(5 s) / D(1 s) = 1.8 at tau 4 s; a
random walk sqrt(5) = 2.24); a law that holds the reported heading tracks a smooth error with
a small lag, and a rough one with the whole of its fast part.

Recorded (PX4 v1.16.0 SIH): the 20 s hover of `px4/hover_noise.tlog.gz` (one vehicle, zero rate
setpoints: nothing holds the heading) and the formation of the 2026-12-04 flight
`flights/2026-12-04/px4_rates_1st/flight.tlog.gz` (four vehicles, the law in rates mode holding
the heading, from the first rates setpoint to the last). Emulated: the hover recording's
setpoints replayed into four px4-personality vehicles (vehicle_emulator.calibration.replay), the same window.
The personality's heading error is a second-order Gauss-Markov process because of these figures
(`attitude_error_order` in vehicle_emulator/config/personality.py). Writes the "## PX4 heading
estimate: the reported heading against the reported yaw rate" section of docs/benchmarks.md.

    python -m benchmarks.calibration.fit_heading_estimate [--no-write]
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.calibration.fit_velocity_consistency import (  # noqa: E402
    DOC,
    HOVER,
    HOVER_S,
    WINDOWS_S,
    mismatch_rms,
    mismatch_table,
    recorded_tlog,
    write_requested,
)
from benchmarks.docsection import publish  # noqa: E402
from vehicle_emulator.calibration import replay as rp  # noqa: E402
from vehicle_emulator.config.personality import PX4_SENSORS  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]

HEADING = "## PX4 heading estimate: the reported heading against the reported yaw rate"
FORMATION = "flights/2026-12-04/px4_rates_1st/flight.tlog.gz"


def _yaw(q1: float, q2: float, q3: float, q4: float) -> float:
    return math.atan2(2.0 * (q1 * q4 + q2 * q3), 1.0 - 2.0 * (q3 * q3 + q4 * q4))


def heading_mismatch(t: np.ndarray, yaw: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """D(w) [deg] (len(WINDOWS_S),) of one vehicle: sample times, yaw [rad], yaw rate [rad/s]."""
    p = np.zeros((len(t), 3))
    v = np.zeros((len(t), 3))
    p[:, 0], v[:, 0] = np.unwrap(yaw), rate
    return np.degrees(mismatch_rms(t, p, v, WINDOWS_S)[:, 0])


def _tlog_rows(name: str) -> tuple[dict[int, list], dict[int, list]]:
    """Per sysid: ATTITUDE_QUATERNION (time_boot s, yaw, yawspeed) and the ground station's
    SET_ATTITUDE_TARGET times on the tlog clock against their vehicle's sample times."""
    att: dict[int, list] = {}
    rates: dict[int, list] = {}
    with recorded_tlog(name) as log:
        last_boot: dict[int, float] = {}
        types = ["ATTITUDE_QUATERNION", "SET_ATTITUDE_TARGET", "SET_POSITION_TARGET_LOCAL_NED"]
        while (m := log.recv_match(type=types)) is not None:
            if m.get_type() == "ATTITUDE_QUATERNION":
                k = m.get_srcSystem()
                last_boot[k] = m.time_boot_ms * 1e-3
                att.setdefault(k, []).append(
                    (last_boot[k], _yaw(m.q1, m.q2, m.q3, m.q4), m.yawspeed))
            elif m.target_system in last_boot:
                k = m.target_system
                if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                    rates[k] = []  # the formation's rates start after the last position target
                else:
                    rates.setdefault(k, []).append(last_boot[k])
    return att, rates


def recorded_hover() -> np.ndarray:
    att, _ = _tlog_rows(HOVER)
    a = np.array(att[1])
    a = a[a[:, 0] >= a[-1, 0] - HOVER_S]
    return heading_mismatch(a[:, 0], a[:, 1], a[:, 2])


def recorded_formation() -> np.ndarray:
    """Mean square over the four vehicles, each from its first formation setpoint to its last."""
    att, rates = _tlog_rows(FORMATION)
    per = []
    for k, a in att.items():
        a = np.array(a)
        t0, t1 = rates[k][0], rates[k][-1]
        a = a[(a[:, 0] >= t0) & (a[:, 0] <= t1)]
        per.append(heading_mismatch(a[:, 0], a[:, 1], a[:, 2]))
    return np.sqrt(np.mean(np.square(per), axis=0))


def emulated_hover(n: int = 4) -> np.ndarray:
    rec = rp.load_recording("px4")
    w0, w1 = rec.hover_window_s
    per = []
    for tr in rp.replay(rec, n=n, until_s=w1 + 0.05):
        aq = tr.streams["ATTITUDE_QUATERNION"]
        aq = aq[(aq[:, 1] >= w0) & (aq[:, 1] <= w1)]
        yaw = np.array([_yaw(*row[5:9]) for row in aq])
        per.append(heading_mismatch(aq[:, 1], yaw, aq[:, 4]))
    return np.sqrt(np.mean(np.square(per), axis=0))


def _row(label: str, d: np.ndarray) -> str:
    return f"| {label} | " + " | ".join(f"{x:.2f}" for x in d) + f" | {d[-1] / d[1]:.1f} |"


def main(argv: list[str] | None = None) -> int:
    write = write_requested(argv, __doc__)
    hover, formation, emulated = recorded_hover(), recorded_formation(), emulated_hover()
    s = PX4_SENSORS
    lines = mismatch_table(
        HEADING, "fit_heading_estimate", "the reported heading's change minus the reported yaw "
        "rate's integral [deg]", _row, (hover, formation, emulated), "D(5 s) / D(1 s)") + [
        "SIH's heading moves without a yaw rate to show for it (its estimator's heading "
        f"correction), smoothly: D grows {hover[-1] / hover[1]:.1f} and "
        f"{formation[-1] / formation[1]:.1f} times from 1 s to 5 s, more than a random walk's "
        "2.24 (a first-order error of 4 s: 1.8). The personality's heading error is second "
        f"order (two poles at 1/tau: 1 sigma {s.attitude_error_std_rad[2]:g} rad, tau "
        f"{s.attitude_error_tau_s[2]:g} s). SIH's hover mismatch is "
        f"{hover[1] / formation[1]:.1f} times its formation's; one stationary error cannot "
        "meet both, and the personality sits between them: over 1 s "
        f"{emulated[1] / hover[1]:.2f} times the hover's and {emulated[1] / formation[1]:.1f} "
        "times the formation's, its hover's detrended heading within the calibration's factor "
        "(docs/emulator.md). A law that holds the reported heading follows a smooth error with "
        "a lag instead of chasing its every jump: with the first-order error the personality "
        "had before (0.042 rad, 4 s) the formation's heading error after 10 s reached 4.8-8.6 "
        "deg against SIH's 1.2 deg (the section \"From the ground, twice: the px4 personality "
        "against the 2026-12-04 SIH flights\" has today's).",
    ]
    publish(DOC, HEADING, "\n".join(lines) + "\n", write=write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
