"""Calibration of vehicle-emu's px4 and ardupilot personalities against the recorded SITL flights.

    .venv/bin/python -m benchmarks.calibration.fit_emulator            # the table
    .venv/bin/python -m benchmarks.calibration.fit_emulator --fit      # refit, then the table
    options: --vehicles N (8), --seed S (0), --markdown FILE (write the table)

The table (docs/emulator.md, "Calibration") replays the recorded setpoint stream
(vehicle_emulator/calibration/replay.py) into N vehicles of each personality and sets the recorded figures
(the JSON summaries of the recordings, from replay.data_dir()) beside the emulated ones: mean
over the vehicles and repetitions, the ratio, and the tolerance of tests/unit/test_calibration.py.

``--fit`` refits what is fitted rather than derived (PX4's rate loop is PX4's and SIH's own
numbers, nothing to fit):
* ArduPilot's reference model (personality.ARDUPILOT_DYNAMICS): per axis group (roll and pitch
  together, yaw) the dead time, natural frequency, damping, gain and angle-error gain, a grid
  flown as one fleet then least squares between the recorded
  ATTITUDE_QUATERNION rates (rate_steps.tlog.gz, on the vehicle's sample times mapped to the
  GCS clock by the README's envelope) and the emulator's own plant kernel (FleetPlant) flying the
  recorded doublets: the rises and plateaus (roll, pitch) or the whole doublet (yaw);
* the noise sizes of both personalities' estimate errors and ArduPilot's stand-in IMU noise:
  multiplicative updates until the median over N replayed hovers meets the recorded std.
It prints the values to write into personality.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import gzip
import shutil
import sys
import tempfile
import time
from collections import deque
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from vehicle_emulator.calibration import metrics as mx  # noqa: E402
from vehicle_emulator.calibration import replay as rp  # noqa: E402
from vehicle_emulator.config.personality import PERSONALITIES, Personality  # noqa: E402
from vehicle_emulator.physics.plant import ControlMode, FleetPlant  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]

# tests/unit/test_calibration.py's tolerances (the issue's): ratio emulated / recorded
TOLERANCE = {"t63_ms": 0.25, "peak": 0.20, "noise": 1.5}


# --- recorded time series (the tlogs) --------------------------------------------------------


def recorded_rates(rec: rp.Recording) -> tuple[np.ndarray, np.ndarray]:
    """ATTITUDE_QUATERNION (rollspeed, pitchspeed, yawspeed) of rate_steps.tlog.gz on the
    vehicle's sample times mapped to the recording's clock (the README's envelope)."""
    from pymavlink import mavutil

    folder = rp.data_dir() / rec.autopilot
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rate_steps.tlog"
        with gzip.open(folder / "rate_steps.tlog.gz", "rb") as src, path.open("wb") as dst:
            shutil.copyfileobj(src, dst)
        conn = mavutil.mavlink_connection(str(path), dialect="all")
        rows = []
        while (m := conn.recv_match(type="ATTITUDE_QUATERNION")) is not None:
            if m.get_srcSystem() == 1:
                rows.append((m._timestamp, m.time_boot_ms * 1e-3, m.rollspeed, m.pitchspeed,
                             m.yawspeed))
    a = np.array(rows)
    import csv

    with (folder / "flight_setpoints.csv").open() as fh:
        first = next(csv.DictReader(fh))
    unix_minus_rec = float(first["t_unix_s"]) - float(first["t_s_from_process_start"])
    rx = a[:, 0] - unix_minus_rec
    return _envelope(rx, a[:, 1]), a[:, 2:5]


def _envelope(rx: np.ndarray, vt: np.ndarray) -> np.ndarray:
    """Sample times: vehicle time plus the smallest offset rx - vt received in the next 0.5 s."""
    off = rx - vt
    out = np.empty_like(off)
    dq: deque[int] = deque()
    k = 0
    for i in range(len(rx)):
        while k < len(rx) and rx[k] <= rx[i] + 0.5:
            while dq and off[dq[-1]] >= off[k]:
                dq.pop()
            dq.append(k)
            k += 1
        while dq[0] < i:
            dq.popleft()
        out[i] = off[dq[0]]
    return vt + out


# --- the plant kernel flying the recorded doublets -------------------------------------------


def kernel_doublets(rec: rp.Recording, personalities: list[Personality], axis: int
                    ) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """FleetPlant with one vehicle per personality, each flying every recorded doublet about
    ``axis`` (FRD body rates, the command switching at the recorded edge send times) from a
    steady hover; returns per doublet (edge0, times from edge0 [s], measured rate (vehicles, t))."""
    out = []
    for d in rec.doublets:
        if d.axis != axis:
            continue
        specs = rp.sitl_airframe(rec.autopilot, len(personalities), rec.law["h_ref"])
        plant = FleetPlant(specs, personalities=personalities)
        plant.mode[:] = ControlMode.RATES
        plant.thrust_cmd_norm[:] = plant.hover_thrust_norm
        lead = 0.5
        plant.step(int(lead / plant.dt_s))
        t0 = plant.time_s
        flu = np.array([1.0, -1.0, -1.0])  # FRD command -> FLU
        times, ys = [], []
        for step in range(int((d.edges_s[2] - d.edges_s[0] + 0.6) / plant.dt_s)):
            t = step * plant.dt_s
            e = np.searchsorted(np.array(d.edges_s) - d.edges_s[0], t, side="right")
            cmd = (0.0, d.amp_radps, -d.amp_radps, 0.0)[e]
            plant.rate_cmd_flu_radps[:, axis] = cmd * flu[axis]
            plant.step(1)
            times.append(plant.time_s - t0)
            ys.append(plant.onboard.rate_meas_flu_radps[:, axis] * flu[axis])
        out.append((d.edges_s[0], np.array(times), np.array(ys).T))
    return out


REF_FIELDS = ("ref_gain", "ref_wn_radps", "ref_zeta", "angle_p", "ref_delay_periods")


def fit_reference(rec: rp.Recording, verbose: bool = True) -> dict:
    """Fit of ArduPilot's reference model (module docstring); returns the per-axis tuples for
    personality.Dynamics."""
    t_s, rates = recorded_rates(rec)
    base = PERSONALITIES[rec.autopilot]
    result = {k: list(getattr(base.dynamics, k)) for k in REF_FIELDS}
    for axes in ((0, 1), (2,)):
        fitter = _GroupFit(rec, t_s, rates, axes, base, result)
        rms, delay, x = fitter.fit_rise() if axes != (2,) else fitter.fit_series()
        for a in axes:
            result["ref_wn_radps"][a], result["ref_zeta"][a], result["ref_gain"][a] = (
                float(v) for v in x[:3])
            result["ref_delay_periods"][a] = delay
            result["angle_p"][a] = float(x[3])
        if verbose:
            period = base.dynamics.control_period_s
            print(f"  {fitter.name}: dead time {delay * period * 1e3:.0f} ms, wn {x[0]:.2f}, "
                  f"zeta {x[1]:.3f}, gain {x[2]:.3f}, angle_p {x[3]:.3f}, residual {rms:.4f}",
                  flush=True)
    return {k: tuple(round(v, 4) if isinstance(v, float) else v for v in vals)
            for k, vals in result.items()}


class _GroupFit:
    """One axis group's fit (roll and pitch share their parameters; yaw has its own)."""

    def __init__(self, rec, t_s, rates, axes, base, result) -> None:
        self.rec, self.t_s, self.rates, self.axes = rec, t_s, rates, axes
        self.base, self.result = base, result
        self.name = "yaw" if axes == (2,) else "roll/pitch"
        self.doublets = [d for d in rec.doublets if d.axis in axes]

    def personality(self, x, delay) -> Personality:
        vals = {k: list(v) for k, v in self.result.items()}
        for a in self.axes:
            vals["ref_wn_radps"][a], vals["ref_zeta"][a], vals["ref_gain"][a] = x[:3]
            vals["ref_delay_periods"][a] = delay
            vals["angle_p"][a] = x[3]
        dyn = dataclasses.replace(self.base.dynamics, **{k: tuple(v) for k, v in vals.items()})
        return dataclasses.replace(self.base, dynamics=dyn)

    def flown(self, candidates):
        """(axis, doublet, recorded mask, model rates (candidates, samples)) of every doublet,
        the candidates flown together, one vehicle each."""
        ps = [self.personality(x, dl) for x, dl in candidates]
        for a in self.axes:
            for e0, tt, yy in kernel_doublets(self.rec, ps, a):
                d = next(d for d in self.doublets if d.edges_s[0] == e0)
                m = (self.t_s > e0 - 0.05) & (self.t_s < d.edges_s[2] + 0.6)
                model = np.array([np.interp(self.t_s[m] - e0, tt, y) for y in yy])
                yield a, d, m, model

    def fit_series(self):
        """Yaw: least squares over the whole doublets, from the best point of a coarse grid."""
        grid = [(wn, z, k, ka) for wn in (5, 7, 9, 12) for z in (0.5, 0.7, 0.9, 1.2)
                for k in (0.8, 0.9, 1.0) for ka in (0.5, 1.5, 3.0)]
        cands = [(x, dl) for dl in range(0, 4) for x in grid]
        rms = [float(np.sqrt(np.mean(r**2))) for r in self.residuals(cands)]
        x0, delay = cands[int(np.argmin(rms))]
        sol = least_squares(lambda x: self.residuals([(x, delay)])[0], x0,
                            bounds=([1.0, 0.2, 0.5, 0.0], [60.0, 3.0, 1.5, 10.0]),
                            diff_step=1e-3)
        return float(np.sqrt(np.mean(sol.fun**2))), delay, sol.x

    def residuals(self, cands):
        res = [[] for _ in cands]
        for a, _d, m, model in self.flown(cands):
            for j in range(len(cands)):
                res[j].append(model[j] - self.rates[m, a])
        return [np.concatenate(r) for r in res]

    def fit_rise(self):
        """Roll/pitch: the model sampled at the recorded sample times, scored on the recorded
        doublets' own figures (t10/t63/t90 and peak of the step and of the reversal; squared
        relative errors per repetition) over a grid flown as one fleet. The time series' least
        squares is dominated by a ~25 Hz ringing after each rise that the model has no mode for,
        and trades the rise for it. The angle-error gain is kept >= 1/s: ArduPilot closes its
        angle loop in body-rate mode (the recorded hover attitude moved 3e-5 rad), and without
        one the emulated attitude would random-walk."""
        grid = [(wn, z, k, ka) for wn in (150, 250, 400, 600) for z in (0.6, 0.8, 1.0, 1.4)
                for k in (0.98, 1.0, 1.02, 1.04) for ka in (1.0, 2.5, 4.5)]
        cands = [(x, dl) for dl in range(0, 7) for x in grid]
        err = np.zeros(len(cands))
        count = 0
        for a, d, m, model in self.flown(cands):
            t = self.t_s[m]
            want = mx.step_response(t, self.rates[m, a], d.edges_s, d.amp_radps)
            for j in range(len(cands)):
                got = mx.step_response(t, model[j], d.edges_s, d.amp_radps)
                for part in ("up", "reversal"):
                    for key in (*RISE_KEYS, "peak"):
                        w, g = want[part][key], got[part][key]
                        err[j] += 1.0 if g is None else ((g - w) / w) ** 2
            count += 2 * (len(RISE_KEYS) + 1)
        j = int(np.argmin(err))
        x, delay = cands[j]
        return float(np.sqrt(err[j] / count)), delay, np.array(x, dtype=float)


RISE_KEYS = ("t10_ms", "t63_ms", "t90_ms")


# --- noise sizes -----------------------------------------------------------------------------


def fit_noise(autopilot: str, n: int, iterations: int = 3, verbose: bool = True) -> dict:
    """Scale the personality's fitted noise sizes until the median over n replayed hovers meets
    the recorded std (multiplicative updates): the velocity errors per axis (north, east, up:
    LOCAL_POSITION_NED's vx, vy, vz), the position error's time constant (the vertical position
    std), the attitude errors on the axes that have one (detrended roll, pitch, yaw) and, for
    ArduPilot, its disturbance (roll and pitch: the limit cycle's gyro std; yaw: ATTITUDE's yaw
    rate), its HIGHRES_IMU z-gyro bias and stand-in accelerometer noise. The time constants,
    the complementary filter's and the limit cycle's frequency are set from the recordings'
    spectra (docs/emulator.md), not here. Returns the new sizes."""
    rec = rp.load_recording(autopilot)
    recorded = rp.recorded_figures(rec)
    per = PERSONALITIES[autopilot]
    sen = per.sensors
    vel = np.array(sen.velocity_error_std_mps, dtype=float)
    tau_p = sen.position_error_tau_s
    att = np.array(sen.attitude_error_std_rad, dtype=float)
    dist = np.array(per.dynamics.disturbance_std_radps2, dtype=float)
    bias = np.array(sen.gyro_bias_std_radps, dtype=float)
    accel = np.array(sen.accel_noise_std_mps2, dtype=float)
    scale_imu = autopilot == "ardupilot"  # PX4's IMU noise is SIH's own, not fitted
    lpn = "LOCAL_POSITION_NED."
    for it in range(iterations):
        sizes = (vel.copy(), tau_p, att.copy(), dist.copy(), bias.copy(), accel.copy())

        def hook(emu, sizes=sizes):
            vel, tau_p, att, dist, bias, accel = sizes
            ob = emu.plant.onboard
            ob.velocity_error_std[:] = vel
            ob.position_error_phi[:] = np.exp(-ob.control_div * emu.plant.dt_s / tau_p)
            ob.attitude_error_std[:] = att
            ob.heading_std_rad[:] = att[2]  # the size a heading schedule scales
            if scale_imu:
                ob.disturbance_std[:] = dist
                ob.gyro_bias_std[:] = bias
                ob.accel_noise_std[:] = accel

        traces = rp.replay(rec, n=n, until_s=rec.hover_window_s[1] + 0.05, emulator_hook=hook)
        med = _median_hover(traces, rec)
        if verbose:
            got = ", ".join(f"{k} {med[k]:.4g} ({recorded[k]:.4g})" for k in (
                f"{lpn}vx", f"{lpn}vy", f"{lpn}vz", f"{lpn}z", "attitude.roll",
                "attitude.pitch", "attitude.yaw"))
            print(f"  {autopilot} noise iteration {it}: {got}", flush=True)
        for j, f in enumerate(("vx", "vy", "vz")):
            vel[j] *= _ratio(recorded[lpn + f], med[lpn + f], vel[j])
        # the reported z falls as the position error slows (the altitude law cancels slow errors)
        tau_p /= _ratio(recorded[f"{lpn}z"], med[f"{lpn}z"], tau_p)
        for j, axis in enumerate(("roll", "pitch", "yaw")):
            att[j] *= _ratio(recorded[f"attitude.{axis}"], med[f"attitude.{axis}"], att[j])
        if scale_imu:
            for j, f in enumerate(("HIGHRES_IMU.xgyro", "HIGHRES_IMU.ygyro",
                                   "ATTITUDE_QUATERNION.yawspeed")):
                dist[j] *= recorded[f] / med[f]
            # the z gyro's part above the bias-free yaw rate is the bias
            z_rec, z_emu = recorded["HIGHRES_IMU.zgyro"], med["HIGHRES_IMU.zgyro"]
            yaw = recorded["ATTITUDE_QUATERNION.yawspeed"]
            if bias[2] > 0.0 and z_emu > yaw:
                bias[2] *= np.sqrt(max(z_rec**2 - yaw**2, 0.0) / (z_emu**2 - yaw**2))
            for j, f in enumerate(("xacc", "yacc", "zacc")):
                accel[j] *= recorded[f"HIGHRES_IMU.{f}"] / med[f"HIGHRES_IMU.{f}"]
    out = {"velocity_error_std_mps": tuple(round(float(v), 4) for v in vel),
           "position_error_tau_s": round(float(tau_p), 3),
           "attitude_error_std_rad": tuple(float(f"{v:.3g}") for v in att)}
    if scale_imu:
        out["disturbance_std_radps2 (Dynamics)"] = tuple(round(float(v), 4) for v in dist)
        out["gyro_bias_std_radps"] = tuple(float(f"{v:.3g}") for v in bias)
        out["accel_noise_std_mps2"] = tuple(round(float(v), 5) for v in accel)
    return out


def _ratio(want: float, got: float, current: float) -> float:
    """Multiplicative update of a noise size: want / got, assuming got grows with the size
    (only the part of got above the noise-free floor does, so the step is damped)."""
    if current <= 0.0:
        return 1.0
    return float(np.clip(want / max(got, 1e-9), 0.2, 5.0))


def _median_hover(traces, rec) -> dict[str, float]:
    per = [rp.emulated_figures([t], rec, parts=("hover",)) for t in traces]
    return {k: float(np.median([p[k] for p in per])) for k in per[0] if not k.endswith(".n")}


# --- the table --------------------------------------------------------------------------------


def tolerance_of(key: str) -> tuple[str, float] | None:
    """Which tolerance a figure is tested against (None: reported only)."""
    name = key.split(".", 1)[1]
    if name == "t63_ms":
        return ("within", TOLERANCE["t63_ms"])
    if name == "peak":
        return ("within", TOLERANCE["peak"])
    if key.split(".")[0] in ("HIGHRES_IMU", "ATTITUDE_QUATERNION", "attitude",
                             "LOCAL_POSITION_NED"):
        return ("factor", TOLERANCE["noise"])
    return None


def verdict(key: str, rec: float | None, emu: float | None) -> str:
    tol = tolerance_of(key)
    if tol is None or rec is None or emu is None or rec == 0:
        return ""
    kind, x = tol
    ratio = emu / rec
    ok = abs(ratio - 1.0) <= x if kind == "within" else 1.0 / x <= ratio <= x
    return "ok" if ok else "**out**"


def table(autopilot: str, n: int, seed: int) -> tuple[list[str], dict, dict]:
    rec = rp.load_recording(autopilot)
    t0 = time.monotonic()
    traces = rp.replay(rec, n=n, seed=seed)
    wall = time.monotonic() - t0
    recorded, emulated = rp.recorded_figures(rec), rp.emulated_figures(traces, rec)
    lines = [f"#### {autopilot} ({n} vehicles, seed {seed}; replay {wall:.0f} s)", "",
             "| figure | recorded | emulated | emulated / recorded | test |",
             "|---|---|---|---|---|"]
    for key, r in recorded.items():
        e = emulated.get(key)
        ratio = "" if (r in (None, 0) or e is None) else f"{e / r:.2f}"
        lines.append(f"| {key} | {_fmt(r)} | {_fmt(e)} | {ratio} | {verdict(key, r, e)} |")
    return lines, recorded, emulated


def _fmt(v: float | None) -> str:
    if v is None:
        return "not reached"
    return f"{v:.4g}" if abs(v) < 10 else f"{v:.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="refit the fitted parameters first")
    ap.add_argument("--vehicles", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--markdown", help="write the table here")
    ap.add_argument("--only", choices=("px4", "ardupilot"))
    args = ap.parse_args(argv)
    if args.fit:
        print("fitting ArduPilot's reference model (rate doublets) ...", flush=True)
        fitted = fit_reference(rp.load_recording("ardupilot"))
        print("ARDUPILOT_DYNAMICS:", fitted)
        for autopilot in ("px4", "ardupilot"):
            print(f"fitting {autopilot}'s noise sizes (hover) ...", flush=True)
            print(f"{autopilot.upper()}_SENSORS:", fit_noise(autopilot, args.vehicles))
    out: list[str] = []
    for autopilot in ("px4", "ardupilot"):
        if args.only and autopilot != args.only:
            continue
        lines, _, _ = table(autopilot, args.vehicles, args.seed)
        out += lines + [""]
        print("\n".join(lines), flush=True)
    if args.markdown:
        Path(args.markdown).write_text("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
