"""Replay of the recorded SITL flight (the recordings: `data_dir`) into an in-process emulator.

The recorded ground station streamed SET_ATTITUDE_TARGET at 100 Hz (body rates + thrust) through a
hover, six rate doublets and two thrust doublets, with its thrust from an altitude law on
LOCAL_POSITION_NED (the data's README, "Altitude law"). ``replay`` does the same to ``n``
identical vehicles of a personality, in simulated time: each setpoint is packed with pymavlink at
its recorded send time (relative to the stream start), the thrust comes from the same law closed
on the emulator's own decoded LOCAL_POSITION_NED, the rate commands and the thrust doublets are
the recorded ones, and the telemetry the emulator sends is decoded. The vehicles differ only in
their sysid, hence in their noise streams, so a replay gives ``n`` realisations at once.

``metrics.py`` turns the traces into the README's figures. Used by tests/unit/test_calibration.py
and benchmarks/calibration/fit_emulator.py. Pure bookkeeping over the Emulator's injected time:
no sockets, no clock.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.calibration import metrics as mx
from vehicle_emulator.config.personality import personality_of
from vehicle_emulator.config.team import VehicleSpec
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink.codec import PeerDecoder

__all__ = [
    "AltitudeLaw",
    "Recording",
    "Trace",
    "data_dir",
    "load_recording",
    "replay",
    "sitl_airframe",
]

GCS_SYSID, GCS_COMPID = 245, 190
STREAM_HZ = 100.0  # the experiment's SET_MESSAGE_INTERVAL requests
STREAMS = {"ATTITUDE_QUATERNION": 31, "LOCAL_POSITION_NED": 32, "HIGHRES_IMU": 105}
LEAD_S = 1.0  # simulated time before the first setpoint (the vehicle holds)
TICK_S = 0.002  # the runner's default loop tick


def data_dir() -> Path:
    """The recordings: $SITL_DATA_DIR, else the team's shared data folder next to the
    repository, else the copy of the replayed files in the repository (tests/data/sitl, for a
    clean checkout)."""
    env = os.environ.get("SITL_DATA_DIR")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[2]
    shared = repo.parent / "shared" / "data" / "sitl"
    return shared if (shared / "px4" / "flight_setpoints.csv").is_file() else (
        repo / "tests" / "data" / "sitl"
    )


@dataclass(frozen=True, slots=True)
class Doublet:
    """A rate doublet: +amp for half_s, -amp for half_s, then 0, about one body axis (FRD)."""

    axis: int  # 0 roll, 1 pitch, 2 yaw
    rep: int
    amp_radps: float
    edges_s: tuple[float, float, float]  # send times of the first setpoint of each value


@dataclass(frozen=True, slots=True)
class Recording:
    """One autopilot's flight recording: the setpoints sent and the summaries' definitions.

    Times are seconds since the recorded process start (the JSON's and CSV's t).
    """

    autopilot: str  # "px4" | "ardupilot": the data folder and the personality replayed
    t_s: np.ndarray  # (k,) send times of the setpoints
    rates_frd_radps: np.ndarray  # (k, 3)
    thrust: np.ndarray  # (k,) what was sent (the law's output or the open-loop doublet)
    phase: np.ndarray  # (k,) str labels
    law: dict[str, float]
    mode_switch_s: float  # DO_SET_MODE into the setpoint mode
    takeoff_s: float | None  # the autopilot's "Takeoff detected" (None: not recorded)
    hover_window_s: tuple[float, float]
    doublets: tuple[Doublet, ...]
    thrust_edges_s: tuple[tuple[float, ...], ...]  # per thrust doublet, its four edges
    thrust_frozen: tuple[float, ...]  # u_frozen of each thrust doublet (as recorded)
    summaries: dict[str, Any] = field(repr=False)  # the JSON files, by experiment name

    @property
    def start_s(self) -> float:
        return float(self.t_s[0])


def load_recording(autopilot: str, directory: Path | None = None) -> Recording:
    """Read ``<dir>/<autopilot>/flight_setpoints.csv`` and the experiment JSONs.
    FileNotFoundError names the folder and $SITL_DATA_DIR when the data is missing."""
    root = (directory or data_dir()) / autopilot
    csv_path = root / "flight_setpoints.csv"
    if not csv_path.is_file():
        raise FileNotFoundError(
            f"{csv_path}: the SITL recordings are missing (set SITL_DATA_DIR to the folder "
            f"holding px4/ and ardupilot/)"
        )
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    summaries = {
        name: json.loads((root / f"{name}.json").read_text())
        for name in ("hover_noise", "rate_steps", "thrust_steps", "timing")
    }
    hover = summaries["hover_noise"]
    switch = [
        c["t"]
        for c in hover["commands"]
        if c["command"] == 176 and "setpoint" in c["label"].lower()
    ]
    if not switch:
        raise ValueError(f"{root}/hover_noise.json: no DO_SET_MODE into the setpoint mode")
    detected = [c["t"] + st["dt_ms"] * 1e-3 for c in hover["commands"]
                for st in c.get("statustexts", []) if st["text"].startswith("Takeoff detected")]
    doublets = tuple(
        Doublet("rpy".index(d["axis"]), int(d["rep"]), float(d["amp_radps"]), tuple(d["t_edges_s"]))
        for d in summaries["rate_steps"]["doublets"]
    )
    steps = summaries["thrust_steps"]["steps"]
    return Recording(
        autopilot=autopilot,
        t_s=np.array([float(r["t_s_from_process_start"]) for r in rows]),
        rates_frd_radps=np.array(
            [[float(r["body_roll_rate"]), float(r["body_pitch_rate"]), float(r["body_yaw_rate"])]
             for r in rows]
        ),
        thrust=np.array([float(r["thrust"]) for r in rows]),
        phase=np.array([r["phase"] for r in rows]),
        law={k: float(v) for k, v in hover["law"].items() if isinstance(v, int | float)},
        mode_switch_s=float(switch[0]),
        takeoff_s=float(detected[0]) if detected else None,
        hover_window_s=(float(hover["window_s"][0]), float(hover["window_s"][1])),
        doublets=doublets,
        thrust_edges_s=tuple(tuple(float(e) for e in s["edges_s"]) for s in steps),
        thrust_frozen=tuple(float(s["u_frozen"]) for s in steps),
        summaries=summaries,
    )


class AltitudeLaw:
    """The recorded ground station's thrust law (the data's README, experiments 4-6):
    thrust = u0 + (u0/g) (wn^2 (h_ref - h) - 2 zeta wn vh + ki I), I = int (h_ref - h) dt,
    clipped to [umin, umax], |I| <= i_max, evaluated at each setpoint tick."""

    def __init__(self, law: dict[str, float], h_ref_m: float) -> None:
        self.u0, self.g = law["u0"], law["g"]
        self.wn, self.zeta, self.ki = law["wn"], law["zeta"], law["ki"]
        self.umin, self.umax, self.i_max = law["umin"], law["umax"], law["i_max"]
        self.h_ref_m = h_ref_m
        self.integral = 0.0
        self._last_t: float | None = None

    def thrust(self, t_s: float, h_m: float, vh_mps: float, frozen: bool = False) -> float:
        """Normalised thrust at time t_s for altitude h (up) and climb rate vh (up)."""
        dt = 0.0 if self._last_t is None else t_s - self._last_t
        self._last_t = t_s
        err = self.h_ref_m - h_m
        if not frozen:
            self.integral = min(max(self.integral + err * dt, -self.i_max), self.i_max)
        acc = self.wn**2 * err - 2.0 * self.zeta * self.wn * vh_mps + self.ki * self.integral
        return min(max(self.u0 + self.u0 / self.g * acc, self.umin), self.umax)


def sitl_airframe(autopilot: str, n: int = 1, h_m: float = 5.0) -> list[VehicleSpec]:
    """``n`` vehicles configured like the recorded SITL airframe, in the air at ``h_m``.

    PX4 SIH quadx (airframe 10040): 1 kg, inertia 0.025/0.025/0.030, X rotors at (+-0.2, +-0.2) m,
    T_MAX 5 N, Q_MAX 0.1 N m. The emulator's mixer (51) is a plus: its roll uses rotors 2 and 4 at
    arm d, so d = 2 * 0.2 m gives SIH's torque for a given differential thrust (exact while no
    rotor saturates); anti-torque C = Q_MAX / T_MAX = 0.02 m.
    ArduCopter SITL "quad" (plus, the emulator's layout): 3 kg, inertia 0.0230/0.0230/0.0459,
    motors 0.175 m from the centre; rotor limit 18.86 N as in the team's sitl4_relay.yaml (the
    GCS's m g / MOT_THST_HOVER; the personality's thrust_scale adds ArduPilot's compensation).
    """
    if autopilot == "px4":
        base = VehicleSpec(
            vehicle_id=1, sysid=1, mass_kg=1.0, inertia_kgm2=(0.025, 0.025, 0.030),
            arm_length_m=0.4, anti_torque_m=0.02, rotor_thrust_max_n=5.0, autopilot="px4",
        )
    elif autopilot == "ardupilot":
        base = VehicleSpec(
            vehicle_id=1, sysid=1, mass_kg=3.0, inertia_kgm2=(0.02297, 0.02297, 0.04594),
            arm_length_m=0.175, anti_torque_m=0.016, rotor_thrust_max_n=18.86,
            autopilot="ardupilot",
        )
    else:
        raise ValueError(f"no recorded SITL airframe for autopilot {autopilot!r}")
    return [
        replace(base, vehicle_id=k + 1, sysid=k + 1, position_enu_m=(0.0, 0.0, h_m))
        for k in range(n)
    ]


class _Collector:
    """A vehicle's link: decodes what the emulator sends, keeps the streams the metrics use."""

    name = "replay"

    def __init__(self, emu: Emulator) -> None:
        self.emu = emu
        self.decoder = PeerDecoder()
        self.rows: dict[str, list[tuple[float, ...]]] = {k: [] for k in STREAMS}
        self.acks: list[tuple[int, int]] = []
        self.last_lpn: tuple[float, float] | None = None  # (h up, vh up)

    def send(self, data: bytes, addr: Any = None) -> None:
        now = self.emu.now_s
        for m in self.decoder.feed(data, "emu"):
            kind = m.get_type()
            if kind == "ATTITUDE_QUATERNION":
                self.rows[kind].append((now, m.time_boot_ms * 1e-3, m.rollspeed, m.pitchspeed,
                                        m.yawspeed, m.q1, m.q2, m.q3, m.q4))
            elif kind == "LOCAL_POSITION_NED":
                self.rows[kind].append((now, m.time_boot_ms * 1e-3, m.x, m.y, m.z, m.vx, m.vy,
                                        m.vz))
                self.last_lpn = (-m.z, -m.vz)
            elif kind == "HIGHRES_IMU":
                self.rows[kind].append((now, m.time_usec * 1e-6, m.xgyro, m.ygyro, m.zgyro,
                                        m.xacc, m.yacc, m.zacc))
            elif kind == "COMMAND_ACK":
                self.acks.append((m.command, m.result))


@dataclass(slots=True)
class Trace:
    """What one replayed vehicle sent, on the recording's clock (s since its process start).

    Each stream is an array of rows: column 0 the emulator's send time, 1 the sample time
    (time_boot_ms / time_usec), then the fields: ATTITUDE_QUATERNION rollspeed, pitchspeed,
    yawspeed, q1..q4; LOCAL_POSITION_NED x, y, z, vx, vy, vz; HIGHRES_IMU x/y/zgyro, x/y/zacc.
    ``setpoints``: send time, roll/pitch/yaw rate, thrust.
    """

    sysid: int
    streams: dict[str, np.ndarray]
    setpoints: np.ndarray


def replay(
    rec: Recording,
    n: int = 4,
    seed: int = 0,
    specs: list[VehicleSpec] | None = None,
    until_s: float | None = None,
    emulator_hook: Any = None,
) -> list[Trace]:
    """Replay ``rec``'s setpoint stream into ``n`` vehicles of its personality (see the module
    docstring); returns one Trace per vehicle. ``until_s`` (recording time) stops early;
    ``emulator_hook(emu)`` may adjust the emulator before the start (the fit script uses it)."""
    law_h_ref = rec.law["h_ref"]
    specs = specs if specs is not None else sitl_airframe(rec.autopilot, n, law_h_ref)
    emu = Emulator(specs, seed=seed, tick_s=TICK_S)
    offset = rec.start_s - LEAD_S  # recording time = emulator time + offset
    if rec.takeoff_s is not None:  # in the air since the recorded takeoff (heading schedule)
        emu.plant.onboard.airborne_since_s[:] = rec.takeoff_s - offset
    if emulator_hook is not None:
        emulator_hook(emu)
    gcs = mavlink.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
    collectors = []
    for node in emu.nodes:
        c = _Collector(emu)
        node.links.append(c)
        collectors.append(c)
    family = personality_of(specs[0].autopilot).protocol.family
    if any(personality_of(s.autopilot).protocol.family != family for s in specs):
        raise ValueError("replay: every vehicle needs the same autopilot family")

    def send(i: int, msg: Any) -> None:
        decoded = PeerDecoder().feed(msg.pack(gcs), "gcs")
        emu.on_messages(emu.nodes[i], collectors[i], decoded, ("127.0.0.1", 14550))

    if family == "ardupilot":  # the recording's vehicle1.parm: the attitude target's thrust is
        for i, node in enumerate(emu.nodes):  # thrust (GUID_OPTIONS bit 3), not a climb rate
            ptype = node.params.definition("GUID_OPTIONS").ptype
            send(i, mavlink.MAVLink_param_set_message(node.sysid, 1, b"GUID_OPTIONS", 8.0,
                                                      int(ptype)))
            if node.params.get_int("GUID_OPTIONS") != 8:
                raise RuntimeError(f"vehicle {node.sysid}: GUID_OPTIONS not set")
    # the experiment's streams at 100 Hz, the others off (they cost decoding, nothing else),
    # requested at staggered times so that the vehicles sample at different phases of the
    # setpoint stream (the 10 ms sampling's quantisation of the delays then averages out)
    t_tick = 0.0
    for i, node in enumerate(emu.nodes):
        while t_tick < 0.1 + i * (1.0 / STREAM_HZ) / len(specs) - 1e-9:
            t_tick += TICK_S
            emu.advance_to(t_tick)
        for msgid in node.telemetry.msgids:
            if msgid == 0:
                continue  # HEARTBEAT
            interval = 1e6 / STREAM_HZ if msgid in STREAMS.values() else -1.0
            send(i, mavlink.MAVLink_command_long_message(
                node.sysid, 1, 511, 0, float(msgid), interval, 0, 0, 0, 0, 0))
        for name, msgid in STREAMS.items():
            got = node.telemetry.interval_us(i, msgid)
            if got != round(1e6 / STREAM_HZ):
                raise RuntimeError(f"vehicle {node.sysid}: {name} interval {got} us after "
                                   f"SET_MESSAGE_INTERVAL {1e6 / STREAM_HZ:.0f}")
    laws = [AltitudeLaw(rec.law, law_h_ref) for _ in specs]
    doublet_of = _thrust_doublet_offsets(rec)
    frozen_u = [0.0] * len(specs)
    law_out: list[list[tuple[float, float]]] = [[] for _ in specs]
    sent: list[list[tuple[float, ...]]] = [[] for _ in specs]
    switched = False
    end = rec.t_s[-1] if until_s is None else min(until_s, rec.t_s[-1])
    for k, t_rec in enumerate(rec.t_s):
        if t_rec > end:
            break
        t_emu = t_rec - offset
        while t_tick + TICK_S <= t_emu + 1e-12:
            t_tick += TICK_S
            emu.advance_to(t_tick)
        emu.advance_to(t_emu)
        if not switched and t_rec >= rec.mode_switch_s:
            for i in range(len(specs)):
                _enter_setpoint_mode(emu, i, family, send, collectors[i])
            switched = True
        rates = rec.rates_frd_radps[k]
        for i, law in enumerate(laws):
            h, vh = collectors[i].last_lpn or (law_h_ref, 0.0)
            offset_u = doublet_of.get(k)
            if offset_u is None:
                u = law.thrust(t_rec, h, vh)
                law_out[i].append((t_rec, u))
            else:
                if offset_u[1]:  # first setpoint of a doublet: freeze at the last 1 s mean
                    frozen_u[i] = float(
                        np.mean([v for t, v in law_out[i] if t >= t_rec - 1.0] or [law.u0])
                    )
                law.thrust(t_rec, h, vh, frozen=True)  # keeps the law's clock, I held
                u = frozen_u[i] + offset_u[0]
            send(i, mavlink.MAVLink_set_attitude_target_message(
                int(t_rec * 1e3) & 0xFFFFFFFF, emu.nodes[i].sysid, 1, 128, [1.0, 0.0, 0.0, 0.0],
                float(rates[0]), float(rates[1]), float(rates[2]), float(u)))
            sent[i].append((t_rec, *(float(r) for r in rates), u))
    while t_tick + TICK_S <= end - offset + 0.3:
        t_tick += TICK_S
        emu.advance_to(t_tick)
    traces = []
    for i, c in enumerate(collectors):
        streams = {}
        for name, rows in c.rows.items():
            a = np.array(rows, dtype=float).reshape(-1, 9 if name == "ATTITUDE_QUATERNION" else 8)
            a[:, :2] += offset
            streams[name] = a
        traces.append(Trace(specs[i].sysid, streams, np.array(sent[i])))
    return traces


def _thrust_doublet_offsets(rec: Recording) -> dict[int, tuple[float, bool]]:
    """Setpoint index -> (thrust offset from u_frozen, first of its doublet) for the recorded
    open-loop thrust doublets (phase thrust_doublet_*)."""
    out: dict[int, tuple[float, bool]] = {}
    d = -1
    prev = ""
    for k, ph in enumerate(rec.phase):
        if ph.startswith("thrust_doublet"):
            first = ph != prev
            if first:
                d += 1
            out[k] = (round((rec.thrust[k] - rec.thrust_frozen[d]) * 10.0) / 10.0, first)
        prev = ph
    return out


def _enter_setpoint_mode(emu: Emulator, i: int, family: str, send: Any, link: _Collector) -> None:
    """DO_SET_MODE into the mode that flies SET_ATTITUDE_TARGET, as the recorded GCS did: PX4
    OFFBOARD (129, 6, 0), ArduPilot GUIDED_NOGPS (1, 20); the last COMMAND_ACK for it must be
    ACCEPTED (PX4 answers twice: the second is the result). RuntimeError otherwise."""
    node = emu.nodes[i]
    p1, p2 = (129.0, 6.0) if family == "px4" else (1.0, 20.0)
    send(i, mavlink.MAVLink_command_long_message(node.sysid, 1, 176, 0, p1, p2, 0, 0, 0, 0, 0))
    emu.send_deferred_acks()
    results = [r for c, r in link.acks if c == 176]
    if not results or results[-1] != 0:
        raise RuntimeError(f"vehicle {node.sysid}: DO_SET_MODE {p2:.0f} not accepted "
                           f"(ACKs {results})")


# --- figures: the same keys from the recording's JSON summaries and from replayed traces ------

AXES = ("roll", "pitch", "yaw")
RATE_KEYS = ("t10_ms", "t63_ms", "t90_ms", "peak", "overshoot_pct", "rev_t63_ms", "rev_peak")
IMU_FIELDS = ("xgyro", "ygyro", "zgyro", "xacc", "yacc", "zacc")
AQ_FIELDS = ("rollspeed", "pitchspeed", "yawspeed")
LPN_FIELDS = ("x", "y", "z", "vx", "vy", "vz")


def recorded_figures(rec: Recording) -> dict[str, float | None]:
    """The recorded figures, read from the JSON summaries: rate steps (ATTITUDE_QUATERNION,
    sample time, mean of the two repetitions), hover noise stds, thrust-step gain and fit, and
    how much older LOCAL_POSITION_NED's samples are than ATTITUDE_QUATERNION's (the median
    latencies above the envelope, timing.json)."""
    out: dict[str, float | None] = {}
    summary = rec.summaries["rate_steps"]["summary"]
    for axis in AXES:
        s = summary[axis[0]]["ATTITUDE_QUATERNION_sampletime"]
        for key in ("t10_ms", "t63_ms", "t90_ms"):
            out[f"{axis}.{key}"] = s[f"step_up_{key}"]
        out[f"{axis}.peak"] = s["peak_radps"]
        out[f"{axis}.overshoot_pct"] = s["overshoot_pct"]
        out[f"{axis}.rev_t63_ms"] = s["reversal_t63_ms"]
        out[f"{axis}.rev_peak"] = s["reversal_peak_radps"]
    hover = rec.summaries["hover_noise"]
    for f in IMU_FIELDS:
        out[f"HIGHRES_IMU.{f}"] = hover["HIGHRES_IMU"][f]["std"]
    for f in AQ_FIELDS:
        out[f"ATTITUDE_QUATERNION.{f}"] = hover["ATTITUDE_QUATERNION"][f]["std"]
    for axis in AXES:
        out[f"attitude.{axis}"] = hover["ATTITUDE_QUATERNION"][f"{axis}_rad"]["std_detrended"]
    for f in LPN_FIELDS:
        out[f"LOCAL_POSITION_NED.{f}"] = hover["LOCAL_POSITION_NED"][f]["std_detrended"]
    thrust = rec.summaries["thrust_steps"]["summary"]
    out["thrust.gain"] = thrust["gain_from_zacc_mean_0p2_0p5_mps2_per_unit"]
    fit = thrust["ensemble"]["zacc_sampletime"]
    out["thrust.dead_time_ms"] = fit["dead_time_ms"]
    out["thrust.tau_ms"] = fit["tau_ms"]
    out["thrust.lag_ms"] = fit["dead_time_ms"] + fit["tau_ms"]
    out["thrust.fit_gain"] = fit["gain"]
    drag = thrust.get("drag_corrected_gain_mps2_per_unit")
    if drag is not None:
        out["thrust.gain_drag_corrected"] = drag
    per = rec.summaries["timing"]["per_message"]
    out["timing.position_age_ms"] = (
        per["LOCAL_POSITION_NED"]["latency_above_envelope_ms"]["p50"]
        - per["ATTITUDE_QUATERNION"]["latency_above_envelope_ms"]["p50"]
    )
    return out


def emulated_figures(
    traces: Sequence[Trace],
    rec: Recording,
    parts: tuple[str, ...] = ("rates", "hover", "thrust", "timing"),
) -> dict[str, float | None]:
    """The same figures from replayed traces: means over every vehicle (and repetition); a
    delay that no repetition reached is None. ``<key>.n`` counts the values averaged.
    ``parts`` limits the figures to rate steps, hover noise, thrust steps and/or timing."""
    acc: dict[str, list[float]] = {}

    def add(key: str, value: float | None) -> None:
        acc.setdefault(key, [])
        if value is not None:
            acc[key].append(value)

    w = rec.hover_window_s
    for tr in traces:
        aq, imu, lpn = (tr.streams[k] for k in ("ATTITUDE_QUATERNION", "HIGHRES_IMU",
                                                  "LOCAL_POSITION_NED"))
        for d in rec.doublets if "rates" in parts else ():
            if aq.shape[0] == 0 or aq[-1, 1] < d.edges_s[2] + mx.PEAK_AFTER_NEXT_EDGE_S:
                continue  # a replay stopped before this doublet (until_s)
            r = mx.step_response(aq[:, 1], aq[:, 2 + d.axis], d.edges_s, d.amp_radps)
            axis = AXES[d.axis]
            for key in ("t10_ms", "t63_ms", "t90_ms", "peak", "overshoot_pct"):
                add(f"{axis}.{key}", r["up"][key])
            add(f"{axis}.rev_t63_ms", r["reversal"]["t63_ms"])
            add(f"{axis}.rev_peak", r["reversal"]["peak"])
        if "hover" in parts:
            _hover_figures(add, aq, imu, lpn, w)
        if "thrust" in parts:
            _thrust_figures(add, imu, lpn, rec)
        if "timing" in parts:
            lat = mx.latency_above_envelope_ms(
                {k: (a[:, 0], a[:, 1]) for k, a in tr.streams.items()})
            add("timing.position_age_ms", lat["LOCAL_POSITION_NED"] - lat["ATTITUDE_QUATERNION"])
    out: dict[str, float | None] = {}
    for key, values in acc.items():
        out[key] = float(np.mean(values)) if values else None
        out[f"{key}.n"] = float(len(values))
    return out


def _hover_figures(add: Any, aq: np.ndarray, imu: np.ndarray, lpn: np.ndarray,
                   w: tuple[float, float]) -> None:
    """Hover-window stds: HIGHRES_IMU and ATTITUDE_QUATERNION rates plain, attitude and
    LOCAL_POSITION_NED about a fitted line (the README's detrending)."""
    for j, f in enumerate(IMU_FIELDS):
        add(f"HIGHRES_IMU.{f}", mx.hover_std(imu[:, 1], imu[:, 2 + j], w))
    for j, f in enumerate(AQ_FIELDS):
        add(f"ATTITUDE_QUATERNION.{f}", mx.hover_std(aq[:, 1], aq[:, 2 + j], w))
    euler = mx.euler_from_quaternions(aq[:, 5:9])
    for j, axis in enumerate(AXES):
        add(f"attitude.{axis}", mx.hover_std(aq[:, 1], euler[:, j], w, detrend=True))
    for j, f in enumerate(LPN_FIELDS):
        add(f"LOCAL_POSITION_NED.{f}", mx.hover_std(lpn[:, 1], lpn[:, 2 + j], w, detrend=True))


def _thrust_figures(add: Any, imu: np.ndarray, lpn: np.ndarray, rec: Recording) -> None:
    """Thrust doublets: per-edge gains of the upward specific force (-zacc), also with the
    linear drag added back (PX4 SIH: + SIH_KDV / SIH_MASS * v_up, v_up from LOCAL_POSITION_NED,
    as the recording's), and the pooled first-order-plus-dead-time fit of one vehicle's eight
    edges (as the recording's)."""
    drag = personality_of(rec.autopilot).dynamics.linear_drag_per_s
    up = -imu[:, 7]
    up_corrected = up - drag * np.interp(imu[:, 1], lpn[:, 1], lpn[:, 7])
    pooled_t, pooled_y = [], []
    for edges in rec.thrust_edges_s:
        for e, du in zip(edges, (0.1, -0.1, -0.1, 0.1), strict=True):
            r = mx.thrust_edge(imu[:, 1], up, e, du)
            add("thrust.gain", r["gain"])
            if drag > 0.0:
                add("thrust.gain_drag_corrected",
                    mx.thrust_edge(imu[:, 1], up_corrected, e, du)["gain"])
            pooled_t.append(r["t_rel_s"])
            pooled_y.append(r["norm"])
    fit = mx.fopdt_fit(np.concatenate(pooled_t), np.concatenate(pooled_y))
    add("thrust.dead_time_ms", fit["dead_time_ms"])
    add("thrust.tau_ms", fit["tau_ms"])
    add("thrust.lag_ms", fit["dead_time_ms"] + fit["tau_ms"])
    add("thrust.fit_gain", fit["gain"])
