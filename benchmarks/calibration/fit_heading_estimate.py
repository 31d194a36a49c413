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
(`attitude_error_order` in vehicle_emulator/config/personality.py). SIH's mismatch depends on the
time since the vehicle left the ground (large for about 20 s, then settling over a minute): D(1 s)
in 5 s bins since each recorded takeoff (the formation flight's four vehicles and the hover's
one) is fitted by the personality's heading schedule (`heading_*` in personality.py; --fit
prints the least-squares fit), and the personality's own D(1 s) by the same phases comes from
four px4-personality vehicles that climb from the ground to 5 m and hold there on their own
position loop, noise on (vehicle_emulator.physics.plant, no MAVLink). Writes the "## PX4 heading
estimate: the reported heading against the reported yaw rate" section of docs/benchmarks.md.

    python -m benchmarks.calibration.fit_heading_estimate [--no-write] [--fit]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

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
)
from benchmarks.docsection import publish  # noqa: E402
from vehicle_emulator.calibration import replay as rp  # noqa: E402
from vehicle_emulator.config.personality import PX4_SENSORS  # noqa: E402
from vehicle_emulator.physics.plant import FleetPlant  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]

HEADING = "## PX4 heading estimate: the reported heading against the reported yaw rate"
FORMATION = "flights/2026-12-04/px4_rates_1st/flight.tlog.gz"
PHASES_S = ((0.0, 20.0), (20.0, 60.0), (60.0, 110.0))  # time since takeoff
BIN_S = 5.0


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


def _one_second_steps(t: np.ndarray, yaw: np.ndarray, rate: np.ndarray, t0: float,
                      t1: float) -> np.ndarray:
    """The 1 s mismatch steps (rad) of windows starting in [t0, t1 - 1 s], a quarter second
    apart: the heading's change minus the yaw rate's integral."""
    keep = np.concatenate([[True], np.diff(t) > 0.0])
    t, yaw, rate = t[keep], yaw[keep], rate[keep]
    r = np.unwrap(yaw) - np.concatenate(
        [[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])
    start = np.arange(max(t0, t[0]), min(t1, t[-1]) - 1.0, 0.25)
    return np.interp(start + 1.0, t, r) - np.interp(start, t, r)


def _after_takeoff(name: str) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per vehicle of the recording ``name``: (time since its takeoff, yaw, yaw rate) from its
    takeoff on: its "Takeoff detected" STATUSTEXT (PX4's land detector; the emulator's takeoff
    is its leaving the ground), at the vehicle's latest attitude sample time."""
    att: dict[int, list] = {}
    takeoff: dict[int, float] = {}
    with recorded_tlog(name) as log:
        while (m := log.recv_match(type=["ATTITUDE_QUATERNION", "STATUSTEXT"])) is not None:
            k = m.get_srcSystem()
            if m.get_type() == "ATTITUDE_QUATERNION":
                att.setdefault(k, []).append(
                    (m.time_boot_ms * 1e-3, _yaw(m.q1, m.q2, m.q3, m.q4), m.yawspeed))
            elif m.text.startswith("Takeoff detected") and k in att and k not in takeoff:
                takeoff[k] = att[k][-1][0]
    tracks = []
    for k in sorted(takeoff):
        a = np.array(att[k])
        a = a[a[:, 0] >= takeoff[k]]
        tracks.append((a[:, 0] - takeoff[k], a[:, 1], a[:, 2]))
    return tracks


def recorded_after_takeoff() -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The formation flight's four vehicles and the hover's one, each from its takeoff."""
    return _after_takeoff(FORMATION) + _after_takeoff(HOVER)


def emulated_after_takeoff(n: int = 4, seconds: float = 112.0, seed: int = 1) -> list[
        tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """n px4-personality vehicles on the ground told to hold 5 m by their own position loop,
    noise on: per vehicle (time since its takeoff, reported yaw, reported yaw rate) at the
    attitude stream's 4 ms."""
    plant = FleetPlant(rp.sitl_airframe("px4", n, 0.0), dt_s=0.001)
    for i in range(n):
        plant.set_noise(i, True)
        plant.seed_noise(i, seed)
        plant.hold_here(i)
        plant.position_sp_enu_m[i, 2] = 5.0
    rows = []
    takeoff = np.full(n, np.nan)
    while plant.time_s < seconds:
        plant.step(4)
        rot = plant.onboard.rotation_est
        rows.append((plant.time_s, np.arctan2(rot[:, 1, 0], rot[:, 0, 0]),
                     plant.onboard.rate_meas_flu_radps[:, 2].copy()))
        takeoff[np.isnan(takeoff) & ~plant.on_ground] = plant.time_s
    t = np.array([r[0] for r in rows])
    yaw, rate = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    return [(t - takeoff[i], yaw[:, i], rate[:, i]) for i in range(n)]


def by_phase(tracks: list, phases: tuple = PHASES_S) -> np.ndarray:
    """D(1 s) [deg] per phase since takeoff, pooled over the tracks (nan: no data)."""
    out = []
    for t0, t1 in phases:
        steps = np.concatenate([_one_second_steps(t, y, r, t0, t1) for t, y, r in tracks])
        out.append(math.degrees(math.sqrt(np.mean(steps ** 2))) if steps.size else math.nan)
    return np.array(out)


def fit_schedule(tracks: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares (on log D) of the personality's heading schedule (heading_takeoff_factor
    x base for heading_takeoff_s, then base -> floor over heading_settle_s) to the recorded
    D(1 s) in BIN_S bins since takeoff; the second-order error's D(1 s) is its 1 sigma times
    sqrt(2 (1 - (1 + 1/tau) exp(-1/tau))). Returns (bin starts, recorded D, fitted
    (base, factor, takeoff_s, settle_s, floor) in rad and s)."""
    tau = PX4_SENSORS.attitude_error_tau_s[2]
    gain = math.sqrt(2.0 * (1.0 - (1.0 + 1.0 / tau) * math.exp(-1.0 / tau)))
    edges = np.arange(0.0, PHASES_S[-1][1], BIN_S)
    starts, recorded = [], []
    for a in edges:
        steps = np.concatenate([_one_second_steps(t, y, r, a, a + BIN_S) for t, y, r in tracks])
        if steps.size >= 20:
            starts.append(a)
            recorded.append(math.degrees(math.sqrt(np.mean(steps ** 2))))
    starts_a, recorded_a = np.array(starts), np.array(recorded)

    def model(p: np.ndarray) -> np.ndarray:
        base, factor, takeoff_s, settle_s, floor = p
        s = starts_a[:, None] + np.linspace(0.0, BIN_S, 11)[None, :]
        std = np.where(s < takeoff_s, factor * base,
                       floor + (base - floor) * np.exp(-np.maximum(s - takeoff_s, 0.0) / settle_s))
        return np.degrees(gain * np.sqrt(np.mean(std ** 2, axis=1)))

    fit = least_squares(lambda p: np.log(model(p)) - np.log(recorded_a),
                        [0.058, 2.0, 20.0, 40.0, 0.005],
                        bounds=([0.01, 1.0, 5.0, 3.0, 0.001], [0.3, 5.0, 40.0, 200.0, 0.05]))
    return starts_a, recorded_a, fit.x


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
    """The hover's setpoints replayed from the air (each vehicle's heading schedule from the
    recorded "Takeoff detected", as replay starts it)."""
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
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--fit", action="store_true",
                    help="also print the heading schedule fitted to the recordings")
    args = ap.parse_args(argv)
    hover, formation, emulated = recorded_hover(), recorded_formation(), emulated_hover()
    recorded_tracks = recorded_after_takeoff()
    phases = (by_phase(recorded_tracks), by_phase(emulated_after_takeoff()))
    if args.fit:
        starts, recorded, p = fit_schedule(recorded_tracks)
        print("recorded D(1 s) by 5 s since takeoff: "
              + " ".join(f"{a:.0f}:{d:.2f}" for a, d in zip(starts, recorded, strict=True)))
        print(f"fitted: base {p[0]:.4f} rad, takeoff factor {p[1]:.2f} for {p[2]:.1f} s, "
              f"settling {p[3]:.1f} s to {p[4]:.4f} rad")
    s = PX4_SENSORS
    phase_names = [f"{a:g}-{b:g} s" for a, b in PHASES_S]
    lines = mismatch_table(
        HEADING, "fit_heading_estimate", "the reported heading's change minus the reported yaw "
        "rate's integral [deg]", _row, (hover, formation, emulated), "D(5 s) / D(1 s)") + [
        "By the time since the vehicle left the ground, D(1 s) [deg]:", "",
        "| source | " + " | ".join(phase_names) + " |",
        "|---|" + "---|" * len(phase_names),
        "| SIH (the formation flight's 4 vehicles and the hover's 1, from each takeoff) | "
        + " | ".join(f"{d:.2f}" for d in phases[0]) + " |",
        "| px4 personality (4 vehicles climbing to 5 m and holding, own position loop) | "
        + " | ".join(f"{d:.2f}" for d in phases[1]) + " |",
        "",
        "SIH's heading moves without a yaw rate to show for it (its estimator's heading "
        f"correction), smoothly: D grows {hover[-1] / hover[1]:.1f} and "
        f"{formation[-1] / formation[1]:.1f} times from 1 s to 5 s, more than a random walk's "
        "2.24 (a first-order error of 4 s: 1.8), and most in the first "
        f"{s.heading_takeoff_s:g} s after a takeoff. The personality's heading error is second "
        f"order (two poles at 1/tau, tau {s.attitude_error_tau_s[2]:g} s) and its size "
        "follows the time since takeoff (`heading_*` in personality.py, fitted by `--fit` to "
        "SIH's D(1 s) in 5 s bins): 1 sigma "
        f"{s.heading_takeoff_factor * s.attitude_error_std_rad[2]:.3g} rad for the first "
        f"{s.heading_takeoff_s:g} s, then from {s.attitude_error_std_rad[2]:g} rad down to "
        f"{s.heading_floor_rad:g} rad with a time constant of {s.heading_settle_s:g} s; each "
        "takeoff starts it again (in the hover's replay, from the recorded \"Takeoff detected\"). The "
        "hover (20-40 s after its takeoff) and the formation (from the law's first setpoint, "
        "some 25-110 s after each takeoff) sit in different phases, which is why one "
        "stationary error could not meet both: the stationary 0.058 rad the personality had "
        "before gave 0.65-0.78 deg over 1 s in every phase, twice SIH's in the formation.",
    ]
    publish(DOC, HEADING, "\n".join(lines) + "\n", write=not args.no_write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
