"""Telemetry scheduler: which message is due for which vehicle, built and framed in batches.

Rates are PX4's onboard-link defaults (docs/emulator.md) unless a vehicle's personality sets its
own (``set_defaults``: ArduPilot streams almost nothing until asked), per vehicle and message,
changeable with MAV_CMD_SET_MESSAGE_INTERVAL. LOCAL_POSITION_NED is sent only with a position
sample taken at or after the vehicle's ``FleetStatus.position_from_ms`` (ArduPilot: once its
EKF has a position; 0 for the others). Each
``collect`` builds every due message type for all vehicles at once from the fleet arrays
(NED/FRD via frames.py), frames them with ``BatchEncoder`` and returns one byte string per
vehicle (PX4 also packs several messages into one UDP datagram). Nominal vehicles report the
true state at ``now``; calibrated personalities (onboard.sensor_model) report their sensor
model's measured rates, HIGHRES_IMU and estimates, stamped with their sample times.
Pure: time is an argument; noise comes from an injected numpy Generator.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from vehicle_emulator.mavlink import hotstreams
from vehicle_emulator.mavlink.codec import CRC_TABLE, BatchEncoder, mavlink
from vehicle_emulator.mavlink.fleet_status import FleetStatus
from vehicle_emulator.mavlink.gnss import GPS_RATE_HZ
from vehicle_emulator.mavlink.payloads import TelemetryPayloads
from vehicle_emulator.physics import frames
from vehicle_emulator.physics.geodesy import DEFAULT_ORIGIN_LLA
from vehicle_emulator.physics.plant import FleetPlant

__all__ = ["DEFAULT_RATES_HZ", "Telemetry"]

DEFAULT_RATES_HZ: dict[str, float] = {
    "HEARTBEAT": 1.0,
    "ATTITUDE": 100.0,
    "ATTITUDE_QUATERNION": 50.0,
    "LOCAL_POSITION_NED": 30.0,
    "ODOMETRY": 30.0,
    "HIGHRES_IMU": 50.0,
    "GLOBAL_POSITION_INT": 50.0,
    "ATTITUDE_TARGET": 10.0,
    "EXTENDED_SYS_STATE": 5.0,
    "SYS_STATUS": 5.0,
    "TIMESYNC": 10.0,
    "BATTERY_STATUS": 0.5,
    "HOME_POSITION": 0.5,
    "GPS_RAW_INT": GPS_RATE_HZ,
}
# Noise standard deviations when EMU_NOISE = 1.
NOISE_POS_M = 0.01
NOISE_VEL_MPS = 0.02
NOISE_ATT_RAD = 0.002
NOISE_GYRO_RADPS = 0.003
NOISE_ACC_MPS2 = 0.05

_NEED_POSITION = frozenset({"LOCAL_POSITION_NED"})
_NO_NOISE = tuple(frames.TelemetryNoise(*(np.zeros((0, 3)) for _ in range(5))))
@njit(cache=True)
def _select_sources(rows, model, truth, est, out):
    """Per vehicle of ``rows``, what telemetry reports into ``out``: the true state ``truth``
    (nominal) or the sensor model's measurements and estimates ``est`` (``model[i]``); all
    three `frames.Reported` (or plain tuples of its fields)."""
    rot, omega, pos, vel, sf = truth
    rot_est, rate_meas, pos_est, vel_est, accel_imu = est
    out_rot, out_w, out_pos, out_vel, out_sf = out
    for i in rows:
        cal = model[i]
        for a in range(3):
            for b in range(3):
                out_rot[i, a, b] = rot_est[i, a, b] if cal else rot[i, a, b]
            out_w[i, a] = rate_meas[i, a] if cal else omega[i, a]
            out_pos[i, a] = pos_est[i, a] if cal else pos[i, a]
            out_vel[i, a] = vel_est[i, a] if cal else vel[i, a]
            out_sf[i, a] = accel_imu[i, a] if cal else sf[i, a]


@njit(cache=True)
def _scatter(out, ln, idx, buf, cursor):
    """Append frame r of ``out`` to vehicle idx[r]'s region of ``buf`` at ``cursor``."""
    for r in range(idx.shape[0]):
        v = idx[r]
        c = cursor[v]
        for j in range(ln[r]):
            buf[c + j] = out[r, j]
        cursor[v] = c + ln[r]


def _msg_class(name: str) -> Any:
    return getattr(mavlink, f"MAVLink_{name.lower()}_message")


class Telemetry(TelemetryPayloads):
    """Per-vehicle, per-message schedule plus batched builders for the whole fleet."""

    def __init__(
        self, n: int, rng: np.random.Generator, start_s: float = 0.0,
        origin_lla: tuple[float, float, float] = DEFAULT_ORIGIN_LLA,
    ) -> None:
        """``origin_lla``: the team frame's origin (lat deg, lon deg, alt m) on the globe."""
        self.origin_lla = origin_lla
        self.names = list(DEFAULT_RATES_HZ)
        self.index = {name: k for k, name in enumerate(self.names)}
        self.msgids = {int(_msg_class(nm).id): k for k, nm in enumerate(self.names)}
        self.n = n
        self.rng = rng
        default = np.array([1.0 / DEFAULT_RATES_HZ[nm] for nm in self.names])
        self.default_interval_s = np.tile(default, (n, 1))  # per vehicle: set_defaults
        self.interval_s = self.default_interval_s.copy()
        # one random phase per vehicle: a vehicle's messages fall on the same ticks (fewer
        # datagrams), different vehicles' messages do not (an even load)
        phase = rng.random((n, 1)) * 0.01
        self.phase_s = start_s + phase[:, 0]
        self.next_due_s = start_s + phase + 0.0 * self.interval_s
        self.encoders = {nm: BatchEncoder(_msg_class(nm)) for nm in self.names}
        self.seq = np.zeros(n, dtype=np.uint8)
        self.sent = np.zeros(len(self.names), dtype=np.int64)
        #: the 100 Hz streams framed in one compiled pass (vehicle_emulator/mavlink/hotstreams.py);
        #: False: through the general path like the others (the reference its tests compare to)
        self.fused = True
        self._hot_cols = np.array([self.index[nm] for nm in hotstreams.NAMES], dtype=np.int64)
        self._hot_compid = self.encoders[hotstreams.NAMES[0]].compid
        # the kernels' bundles go as plain tuples: numba types a plain tuple of arrays in C but a
        # named one in Python (some 10 us a collect for these and _derive's at 24 vehicles)
        self._hot_schedule = tuple(hotstreams.Schedule(self.next_due_s, self.interval_s,
                                                        self._hot_cols, self.sent))
        self._hot_senders: tuple | None = None
        self._hot_out = np.empty((n, hotstreams.ROW_BYTES), dtype=np.uint8)
        self._hot_len = np.zeros(n, dtype=np.int64)
        self._d: dict[str, Any] | None = None
        self._builders = {
            "HEARTBEAT": self._heartbeat,
            "ATTITUDE": self._attitude,
            "ATTITUDE_QUATERNION": self._attitude_quaternion,
            "LOCAL_POSITION_NED": self._local_position,
            "ODOMETRY": self._odometry,
            "HIGHRES_IMU": self._highres_imu,
            "GLOBAL_POSITION_INT": self._global_position,
            "ATTITUDE_TARGET": self._attitude_target,
            "EXTENDED_SYS_STATE": self._extended_sys_state,
            "SYS_STATUS": self._sys_status,
            "TIMESYNC": self._timesync,
            "BATTERY_STATUS": self._battery_status,
            "HOME_POSITION": self._home_position,
            "GPS_RAW_INT": self._gps_raw_int,
        }

    # --- schedule -----------------------------------------------------------------------------

    def set_defaults(
        self, vehicle: int, rates_hz: dict[str, float], delayed: tuple[str, ...] = (),
        now_s: float = 0.0,
    ) -> None:
        """A vehicle's default rates (0: not sent unless requested), which also become its
        current ones; a message not named keeps PX4's rate. The first of a ``delayed`` message
        comes one interval after ``now_s`` (ArduPilot's first TIMESYNC request: 10 s)."""
        for name, hz in rates_hz.items():
            k = self.index[name]
            interval = math.inf if hz <= 0.0 else 1.0 / hz
            self.default_interval_s[vehicle, k] = interval
            self.interval_s[vehicle, k] = interval
            if math.isinf(interval) or name in delayed:
                self.next_due_s[vehicle, k] = now_s + interval

    def requested_only(self, vehicle: int) -> None:
        """``--streams requested`` (PX4's MAVLink instance modes, a mode with no streams):
        every stream of the vehicle off but HEARTBEAT, until a SET_MESSAGE_INTERVAL (or a
        REQUEST_MESSAGE, once) asks for it; interval 0 ("default rate") then gives the
        personality's rate."""
        hb = self.index["HEARTBEAT"]
        for k in range(len(self.names)):
            if k != hb:
                self.interval_s[vehicle, k] = math.inf
                self.next_due_s[vehicle, k] = math.inf

    def set_interval(self, vehicle: int, msgid: int, interval_us: float, now_s: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL semantics: -1 off, 0 default, > 0 period in us. The
        first message comes at the first point of the vehicle's phase grid (phase + j interval)
        after ``now_s``, within one interval: a ground station setting its rates one command at
        a time must not scatter a vehicle's messages over several ticks, each its own datagram.
        Returns False for a message the emulator does not stream."""
        k = self.msgids.get(int(msgid))
        if k is None:
            return False
        if interval_us < 0:
            self.interval_s[vehicle, k] = math.inf
        elif interval_us == 0:
            self.interval_s[vehicle, k] = self.default_interval_s[vehicle, k]
        else:
            self.interval_s[vehicle, k] = max(interval_us * 1e-6, 1e-3)
        iv = self.interval_s[vehicle, k]
        if math.isinf(iv):
            self.next_due_s[vehicle, k] = now_s + 1e9
        else:  # on the vehicle's phase grid: its messages keep sharing ticks (and datagrams)
            phase = float(self.phase_s[vehicle])
            self.next_due_s[vehicle, k] = phase + iv * (math.floor((now_s - phase) / iv) + 1.0)
        return True

    def interval_us(self, vehicle: int, msgid: int) -> int:
        """Current interval of a streamed message (-1 off); KeyError for others."""
        s = self.interval_s[vehicle, self.msgids[int(msgid)]]
        return -1 if math.isinf(s) else int(round(s * 1e6))

    def collect(
        self, now_s: float, plant: FleetPlant, status: FleetStatus, enabled: np.ndarray
    ) -> dict[int, bytes]:
        """Frames of every message due at ``now_s``: {vehicle index: datagram bytes}.

        ``enabled`` (n,) bool masks vehicles whose link is up; disabled vehicles' schedules
        still advance (their messages are lost, as on a dead link)."""
        due = self.next_due_s <= now_s
        if not due.any():
            return {}
        self._derive(plant, status, np.flatnonzero(due.any(axis=1)))
        d = self._d
        assert d is not None
        t_pos_ms = d["t_pos_ms"]
        if self.fused:
            per_vehicle = self._frame_hot(now_s, status, enabled).copy()
            due[:, self._hot_cols] = False
        else:
            per_vehicle = np.zeros(self.n, dtype=np.int64)
        chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for k in np.flatnonzero(due.any(axis=0)):
            idx = np.flatnonzero(due[:, k])
            nxt = self.next_due_s[idx, k] + self.interval_s[idx, k]
            self.next_due_s[idx, k] = np.where(nxt <= now_s, now_s + self.interval_s[idx, k], nxt)
            idx = idx[enabled[idx]]
            name = self.names[k]
            if name in _NEED_POSITION:
                idx = idx[t_pos_ms[idx] >= status.position_from_ms[idx]]
            elif name == "ATTITUDE_TARGET":
                idx = idx[status.attitude_target[idx]]
            if idx.size == 0:
                continue
            enc = self.encoders[name]
            rows = enc.empty(idx.size)
            self._builders[name](rows, idx, now_s, plant, status)
            out, ln = enc.encode(rows, idx, status.sysid, self.seq)
            self.sent[k] += idx.size
            per_vehicle[idx] += ln
            chunks.append((idx, out, ln))
        ends = np.cumsum(per_vehicle)
        if ends[-1] == 0:
            return {}
        starts = ends - per_vehicle
        cursor = starts.copy()
        buf = np.empty(int(ends[-1]), dtype=np.uint8)
        if self.fused:  # each vehicle's hot frames first: their sequence numbers came first
            hotstreams.place_rows(self._hot_out, self._hot_len, buf, starts, cursor)
        for idx, out, ln in chunks:
            _scatter(out, ln, idx, buf, cursor)
        data = buf.tobytes()
        return {int(v): data[starts[v] : ends[v]] for v in np.flatnonzero(per_vehicle).tolist()}

    def _frame_hot(self, now_s: float, status: FleetStatus, enabled: np.ndarray) -> np.ndarray:
        """The 100 Hz streams due at ``now_s`` framed into ``_hot_out`` (hotstreams.py);
        returns each vehicle's bytes of them."""
        d = self._d
        assert d is not None
        values = hotstreams.StreamValues(
            d["q"], d["w_frd"], d["t_att_ms"], d["pos_ned"], status.origin_ned_m, d["vel_ned"],
            d["t_pos_ms"], status.position_from_ms, d["acc_frd"], d["gimu_frd"], d["t_att_us"],
            d["z_up"], self.origin_lla[2])
        senders = self._hot_senders
        if senders is None or senders[0] is not enabled or senders[1] is not status.sysid:
            senders = self._hot_senders = tuple(
                hotstreams.Senders(enabled, status.sysid, self._hot_compid, self.seq))
        hotstreams.frame_streams(now_s, self._hot_schedule, senders, tuple(values), CRC_TABLE,
                                 self._hot_out, self._hot_len)
        return self._hot_len

    # --- derived quantities, once per collect --------------------------------------------------

    def _derive(self, plant: FleetPlant, status: FleetStatus, rows: np.ndarray) -> None:
        """NED/FRD views of the vehicles ``rows`` (numba; the others' are left as they were:
        only the vehicles with a message due are read), plus noise for those with EMU_NOISE."""
        n = plant.n
        d = self._d
        if d is None or d["pos_ned"].shape[0] != n:
            d = self._d = {
                "r_ned": np.empty((n, 3, 3)),
                "q": np.empty((n, 4)),
                "eul": np.empty((n, 3)),
                "w_frd": np.empty((n, 3)),
                "pos_ned": np.empty((n, 3)),
                "vel_ned": np.empty((n, 3)),
                "vel_frd": np.empty((n, 3)),
                "acc_frd": np.empty((n, 3)),
                "q_sp": np.empty((n, 4)),
                "rate_sp_frd": np.empty((n, 3)),
                "yaw_ned": np.empty(n),
            }
            d["ned"] = tuple(frames.NedFrd(d["r_ned"], d["q"], d["eul"], d["w_frd"], d["pos_ned"],
                                           d["vel_ned"], d["vel_frd"], d["acc_frd"], d["q_sp"],
                                           d["rate_sp_frd"], d["yaw_ned"]))
        noisy = rows[status.noise[rows]]
        if noisy.size:
            k = noisy.size
            nz = tuple(frames.TelemetryNoise(
                self.rng.normal(0.0, NOISE_ATT_RAD, (k, 3)),
                self.rng.normal(0.0, NOISE_GYRO_RADPS, (k, 3)),
                self.rng.normal(0.0, NOISE_POS_M, (k, 3)),
                self.rng.normal(0.0, NOISE_VEL_MPS, (k, 3)),
                self.rng.normal(0.0, NOISE_ACC_MPS2, (k, 3)),
            ))
        else:
            nz = _NO_NOISE
        ob = plant.onboard
        model = ob.sensor_model
        modelled = bool(model.any())
        if d.get("sources_of") is not plant:  # the plant's arrays, bundled once
            d["sources_of"] = plant
            d["truth"] = tuple(frames.Reported(plant.rotation, plant.omega_flu_radps,
                                               plant.position_enu_m, plant.velocity_enu_mps,
                                               plant.specific_force_flu_mps2))
            d["est"] = tuple(frames.Reported(ob.rotation_est, ob.rate_meas_flu_radps,
                                             ob.position_est_enu_m, ob.velocity_est_enu_mps,
                                             ob.accel_imu_flu_mps2))
        if modelled:
            if "src" not in d or d["src"][0].shape[0] != n:
                d["src"] = tuple(frames.Reported(np.empty((n, 3, 3)), np.empty((n, 3)),
                                                 np.empty((n, 3)), np.empty((n, 3)),
                                                 np.empty((n, 3))))
                d["gimu_frd"] = np.empty((n, 3))
            _select_sources(rows, model, d["truth"], d["est"], d["src"])
            src = d["src"]
        else:
            src = d["truth"]
        frames.fleet_to_ned_frd(src, plant.attitude_sp, plant.rate_sp_flu_radps, rows, noisy, nz,
                                d["ned"])
        if modelled:  # HIGHRES_IMU gyro: the IMU's own (PX4: raw means), FLU -> FRD
            g = d["gimu_frd"]
            g[rows] = d["w_frd"][rows]
            imu = rows[model[rows]]
            g[imu] = ob.gyro_imu_flu_radps[imu] * np.array([1.0, -1.0, -1.0])
        else:
            d["gimu_frd"] = d["w_frd"]
        att_s, pos_s = plant.sample_time_s()
        d["t_att_ms"] = (att_s * 1e3).astype(np.int64)
        d["t_att_us"] = (att_s * 1e6).astype(np.int64)
        d["t_pos_ms"] = (pos_s * 1e3).astype(np.int64)
        d["t_pos_us"] = (pos_s * 1e6).astype(np.int64)
        # Reported.pos_m's heights, in one layout for frame_streams
        d["z_up"] = np.ascontiguousarray(src[2][:, 2])
