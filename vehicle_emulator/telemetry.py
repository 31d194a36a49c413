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
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from vehicle_emulator import frames, hotstreams
from vehicle_emulator.codec import CRC_TABLE, BatchEncoder, mavlink
from vehicle_emulator.geodesy import enu_to_geodetic
from vehicle_emulator.gnss import GPS_RATE_HZ, fill_gps_raw_int
from vehicle_emulator.plant import FleetPlant

__all__ = [
    "DEFAULT_ORIGIN_LLA", "DEFAULT_RATES_HZ", "FleetStatus", "Telemetry", "HOME_LAT_DEG",
    "HOME_LON_DEG",
]

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
# The team frame's origin on the globe when the team file states none (its `frame.origin`):
# PX4 SITL's default home (Zurich). Geodetic coordinates (GLOBAL_POSITION_INT, HOME_POSITION,
# GPS_GLOBAL_ORIGIN) are exact WGS-84 (geodesy.py).
HOME_LAT_DEG = 47.397742
HOME_LON_DEG = 8.545594
HOME_ALT_M = 488.0
DEFAULT_ORIGIN_LLA = (HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)
# Noise standard deviations when EMU_NOISE = 1.
NOISE_POS_M = 0.01
NOISE_VEL_MPS = 0.02
NOISE_ATT_RAD = 0.002
NOISE_GYRO_RADPS = 0.003
NOISE_ACC_MPS2 = 0.05

_NEED_POSITION = frozenset({"LOCAL_POSITION_NED"})
_NO_NOISE = {key: np.zeros((0, 3)) for key in ("att", "gyro", "pos", "vel", "acc")}
_GPS = 0x20  # MAV_SYS_STATUS_SENSOR_GPS: present and enabled once there is a global position
_SENSORS = 0x1 | 0x2 | 0x4 | 0x8 | 0x400 | 0x800 | 0x1000 | 0x8000 | 0x200000
_PREARM_CHECK = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK: health set while arming would pass


@dataclass(slots=True)
class FleetStatus:
    """Per-vehicle autopilot status arrays the runner keeps up to date (n,)."""

    sysid: np.ndarray  # uint8
    armed: np.ndarray  # bool
    custom_mode: np.ndarray  # uint32
    base_mode_flags: np.ndarray  # uint8, without SAFETY_ARMED
    landed_state: np.ndarray  # uint8 MAV_LANDED_STATE
    system_status: np.ndarray  # uint8 MAV_STATE
    prearm_ok: np.ndarray  # bool: SYS_STATUS pre-arm check health bit
    position_ok: np.ndarray  # bool: SYS_STATUS GPS bit present and enabled (global position)
    mav_autopilot: np.ndarray  # uint8 MAV_AUTOPILOT of the personality
    origin_ned_m: np.ndarray  # (n, 3) EKF origin in the team frame (NED): LOCAL_POSITION_NED zero
    home_ned_m: np.ndarray  # (n, 3) home in the team frame (NED)
    noise: np.ndarray  # bool
    #: int64 time_boot_ms from which the estimator has a position: LOCAL_POSITION_NED is sent only
    #: with samples taken then or later (a sample stamped before it has no estimate behind it)
    position_from_ms: np.ndarray
    vtol_state: np.ndarray  # uint8 EXTENDED_SYS_STATE.vtol_state (ArduCopter: MC, 3)
    battery_remaining: np.ndarray  # 0..1
    battery_voltage_v: np.ndarray
    battery_current_a: np.ndarray
    errors_comm: np.ndarray  # uint16: rejected input so far
    #: bool: the autopilot publishes an attitude/rates setpoint (else no ATTITUDE_TARGET is sent,
    #: whatever its interval: PX4 sends one only per new setpoint)
    attitude_target: np.ndarray

    #: The columns a vehicle refreshes at the autopilot's rate (`VehicleNode.status_row`), in
    #: the row's order.
    ROW_COLUMNS = ("armed", "system_status", "prearm_ok", "position_ok", "custom_mode",
                   "base_mode_flags", "landed_state", "errors_comm", "attitude_target")

    def write_row(self, i: int, row: tuple) -> None:
        """One vehicle's `ROW_COLUMNS` values."""
        for name, value in zip(self.ROW_COLUMNS, row, strict=True):
            getattr(self, name)[i] = value

    def write_rows(self, rows: list[tuple]) -> None:
        """Every vehicle's `ROW_COLUMNS` values (``rows[i]``: vehicle i's), a column at a time:
        at 240 vehicles and 50 Hz, a numpy write per value was a tenth of the fleet's time."""
        for name, column in zip(self.ROW_COLUMNS, zip(*rows, strict=True), strict=True):
            getattr(self, name)[:] = column

    def refresh_battery(self, charge_used_c: np.ndarray, thrust_n: np.ndarray,
                        capacity_c: np.ndarray | float, which: slice = slice(None)) -> None:
        """The battery model of the vehicles ``which`` (after their ``armed``): the charge used
        of ``capacity_c`` [C], 13.2 V empty to 16.8 V full, 0.5 A + 0.8 A per newton of thrust
        while armed."""
        remaining = np.maximum(0.0, 1.0 - charge_used_c[which] / capacity_c)
        self.battery_remaining[which] = remaining
        self.battery_voltage_v[which] = 13.2 + 3.6 * remaining
        self.battery_current_a[which] = np.where(self.armed[which], 0.5 + 0.8 * thrust_n[which],
                                                 0.0)

    @classmethod
    def create(cls, sysids: list[int]) -> FleetStatus:
        """Defaults for ``len(sysids)`` vehicles."""
        n = len(sysids)
        return cls(
            sysid=np.array(sysids, dtype=np.uint8),
            armed=np.zeros(n, dtype=bool),
            custom_mode=np.zeros(n, dtype=np.uint32),
            base_mode_flags=np.ones(n, dtype=np.uint8),
            landed_state=np.ones(n, dtype=np.uint8),
            system_status=np.full(n, 3, dtype=np.uint8),
            prearm_ok=np.ones(n, dtype=bool),
            position_ok=np.ones(n, dtype=bool),
            mav_autopilot=np.full(n, 12, dtype=np.uint8),
            origin_ned_m=np.zeros((n, 3)),
            home_ned_m=np.zeros((n, 3)),
            noise=np.zeros(n, dtype=bool),
            position_from_ms=np.zeros(n, dtype=np.int64),
            vtol_state=np.zeros(n, dtype=np.uint8),
            battery_remaining=np.ones(n),
            battery_voltage_v=np.full(n, 16.8),
            battery_current_a=np.zeros(n),
            errors_comm=np.zeros(n, dtype=np.uint16),
            attitude_target=np.ones(n, dtype=bool),
        )


@njit(cache=True)
def _select_sources(rows, model, rot, rot_est, omega, rate_meas, pos, pos_est, vel, vel_est, sf,
                    accel_imu, out_rot, out_w, out_pos, out_vel, out_sf):
    """Per vehicle of ``rows``, what telemetry reports: the true state (nominal) or the sensor
    model's measurements and estimates (``model[i]``)."""
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


def geodetic_of_ned(
    ned_m: np.ndarray, origin_lla: tuple[float, float, float] = DEFAULT_ORIGIN_LLA
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Team-frame NED points (..., 3) -> (lat deg, lon deg, altitude m) on the WGS-84
    ellipsoid (the emulator reports ellipsoid heights as AMSL: no geoid model); the team
    frame's origin is ``origin_lla`` (lat deg, lon deg, alt m)."""
    ned = np.asarray(ned_m, dtype=float)
    enu = np.stack((ned[..., 1], ned[..., 0], -ned[..., 2]), axis=-1)
    return enu_to_geodetic(enu, *origin_lla)


def _msg_class(name: str) -> Any:
    return getattr(mavlink, f"MAVLink_{name.lower()}_message")


class Telemetry:
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
        #: the 100 Hz streams framed in one compiled pass (vehicle_emulator/hotstreams.py);
        #: False: through the general path like the others (the reference its tests compare to)
        self.fused = True
        self._hot_cols = np.array([self.index[nm] for nm in hotstreams.NAMES], dtype=np.int64)
        self._hot_compid = self.encoders[hotstreams.NAMES[0]].compid
        self._hot_out = np.empty((n, hotstreams.ROW_BYTES), dtype=np.uint8)
        self._hot_len = np.zeros(n, dtype=np.int64)
        self._d: dict[str, np.ndarray] | None = None
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
        hotstreams.frame_streams(
            now_s, self.next_due_s, self.interval_s, self._hot_cols, enabled,
            status.position_from_ms, d["q"], d["w_frd"], d["t_att_ms"], d["pos_ned"],
            status.origin_ned_m, d["vel_ned"], d["t_pos_ms"], d["acc_frd"], d["gimu_frd"],
            d["t_att_us"], d["z_up"], self.origin_lla[2], status.sysid, self._hot_compid, self.seq,
            CRC_TABLE, self._hot_out, self._hot_len, self.sent)
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
        noisy = rows[status.noise[rows]]
        if noisy.size:
            k = noisy.size
            nz = {
                "att": self.rng.normal(0.0, NOISE_ATT_RAD, (k, 3)),
                "gyro": self.rng.normal(0.0, NOISE_GYRO_RADPS, (k, 3)),
                "pos": self.rng.normal(0.0, NOISE_POS_M, (k, 3)),
                "vel": self.rng.normal(0.0, NOISE_VEL_MPS, (k, 3)),
                "acc": self.rng.normal(0.0, NOISE_ACC_MPS2, (k, 3)),
            }
        else:
            nz = _NO_NOISE
        ob = plant.onboard
        model = ob.sensor_model
        modelled = bool(model.any())
        if modelled:
            if "src_rot" not in d or d["src_rot"].shape[0] != n:
                d["src_rot"], d["src_w"] = np.empty((n, 3, 3)), np.empty((n, 3))
                d["src_pos"], d["src_vel"] = np.empty((n, 3)), np.empty((n, 3))
                d["src_sf"], d["gimu_frd"] = np.empty((n, 3)), np.empty((n, 3))
            _select_sources(
                rows,
                model,
                plant.rotation,
                ob.rotation_est,
                plant.omega_flu_radps,
                ob.rate_meas_flu_radps,
                plant.position_enu_m,
                ob.position_est_enu_m,
                plant.velocity_enu_mps,
                ob.velocity_est_enu_mps,
                plant.specific_force_flu_mps2,
                ob.accel_imu_flu_mps2,
                d["src_rot"],
                d["src_w"],
                d["src_pos"],
                d["src_vel"],
                d["src_sf"],
            )
            src = (d["src_rot"], d["src_w"], d["src_pos"], d["src_vel"], d["src_sf"])
        else:
            src = (
                plant.rotation,
                plant.omega_flu_radps,
                plant.position_enu_m,
                plant.velocity_enu_mps,
                plant.specific_force_flu_mps2,
            )
        frames.fleet_to_ned_frd(
            *src,
            plant.attitude_sp,
            plant.rate_sp_flu_radps,
            rows,
            noisy,
            nz["att"],
            nz["gyro"],
            nz["pos"],
            nz["vel"],
            nz["acc"],
            d["r_ned"],
            d["q"],
            d["eul"],
            d["w_frd"],
            d["pos_ned"],
            d["vel_ned"],
            d["vel_frd"],
            d["acc_frd"],
            d["q_sp"],
            d["rate_sp_frd"],
            d["yaw_ned"],
        )
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
        d["z_up"] = np.ascontiguousarray(src[2][:, 2])  # one layout for frame_streams

    # --- builders: fill payload rows for vehicles idx ----------------------------------------

    def _heartbeat(self, rows, idx, now_s, plant, status) -> None:
        armed = status.armed[idx]
        rows["custom_mode"] = status.custom_mode[idx]
        rows["type"] = 2  # MAV_TYPE_QUADROTOR
        rows["autopilot"] = status.mav_autopilot[idx]
        rows["base_mode"] = status.base_mode_flags[idx] | np.where(armed, 128, 0).astype(np.uint8)
        rows["system_status"] = status.system_status[idx]
        rows["mavlink_version"] = 3

    def _attitude(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        eul, w = d["eul"][idx], d["w_frd"][idx]
        rows["time_boot_ms"] = d["t_att_ms"][idx]
        rows["roll"], rows["pitch"], rows["yaw"] = eul[:, 0], eul[:, 1], eul[:, 2]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]

    def _attitude_quaternion(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        q, w = d["q"][idx], d["w_frd"][idx]
        rows["time_boot_ms"] = d["t_att_ms"][idx]
        rows["q1"], rows["q2"], rows["q3"], rows["q4"] = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]

    def _local_position(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p, v = d["pos_ned"][idx] - status.origin_ned_m[idx], d["vel_ned"][idx]
        rows["time_boot_ms"] = d["t_pos_ms"][idx]
        rows["x"], rows["y"], rows["z"] = p[:, 0], p[:, 1], p[:, 2]
        rows["vx"], rows["vy"], rows["vz"] = v[:, 0], v[:, 1], v[:, 2]

    def _odometry(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p, v, w = d["pos_ned"][idx] - status.origin_ned_m[idx], d["vel_frd"][idx], d["w_frd"][idx]
        rows["time_usec"] = d["t_pos_us"][idx]
        rows["frame_id"] = 1  # MAV_FRAME_LOCAL_NED
        rows["child_frame_id"] = 12  # MAV_FRAME_BODY_FRD: the twist is in the body frame
        rows["x"], rows["y"], rows["z"] = p[:, 0], p[:, 1], p[:, 2]
        rows["q"] = d["q"][idx]
        rows["vx"], rows["vy"], rows["vz"] = v[:, 0], v[:, 1], v[:, 2]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]
        rows["pose_covariance"][:, 0] = np.nan
        rows["velocity_covariance"][:, 0] = np.nan
        rows["quality"] = 100

    def _highres_imu(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        acc, w = d["acc_frd"][idx], d["gimu_frd"][idx]
        rows["time_usec"] = d["t_att_us"][idx]
        rows["xacc"], rows["yacc"], rows["zacc"] = acc[:, 0], acc[:, 1], acc[:, 2]
        rows["xgyro"], rows["ygyro"], rows["zgyro"] = w[:, 0], w[:, 1], w[:, 2]
        z = d["z_up"][idx]
        alt0_m = self.origin_lla[2]
        rows["abs_pressure"] = 1013.25 * (1.0 - 2.25577e-5 * (alt0_m + z)) ** 5.25588
        rows["pressure_alt"] = alt0_m + z
        rows["temperature"] = 25.0
        rows["fields_updated"] = 0x3F | 0x200 | 0x800 | 0x1000

    def _global_position(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p = d["pos_ned"][idx]
        v = d["vel_ned"][idx]
        lat, lon, alt = geodetic_of_ned(p, self.origin_lla)
        rows["time_boot_ms"] = d["t_pos_ms"][idx]
        rows["lat"] = np.round(lat * 1e7)
        rows["lon"] = np.round(lon * 1e7)
        rows["alt"] = np.round(alt * 1e3)
        rows["relative_alt"] = np.round((status.home_ned_m[idx, 2] - p[:, 2]) * 1e3)
        rows["vx"] = np.round(v[:, 0] * 100)
        rows["vy"] = np.round(v[:, 1] * 100)
        rows["vz"] = np.round(v[:, 2] * 100)
        rows["hdg"] = np.round(np.degrees(d["yaw_ned"][idx]) * 100).astype(np.int64) % 36000

    def _attitude_target(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        w = d["rate_sp_frd"][idx]
        rows["time_boot_ms"] = int(now_s * 1e3)
        rows["q"] = d["q_sp"][idx]
        rows["body_roll_rate"], rows["body_pitch_rate"] = w[:, 0], w[:, 1]
        rows["body_yaw_rate"] = w[:, 2]
        rows["thrust"] = plant.thrust_sp_norm[idx]

    def _extended_sys_state(self, rows, idx, now_s, plant, status) -> None:
        rows["landed_state"] = status.landed_state[idx]
        rows["vtol_state"] = status.vtol_state[idx]

    def _sys_status(self, rows, idx, now_s, plant, status) -> None:
        # PX4 v1.16.0 SIH: the GPS health bit is set from boot, but GPS is present and enabled
        # only once the estimator has a global position (with the pre-arm bit, when armable)
        gps = np.where(status.position_ok[idx], _GPS, 0).astype(np.uint32)
        rows["onboard_control_sensors_present"] = _SENSORS | _PREARM_CHECK | gps
        rows["onboard_control_sensors_enabled"] = _SENSORS | _PREARM_CHECK | gps
        rows["onboard_control_sensors_health"] = _SENSORS | _GPS | np.where(
            status.prearm_ok[idx], _PREARM_CHECK, 0
        ).astype(np.uint32)
        rows["load"] = 200
        rows["voltage_battery"] = np.round(status.battery_voltage_v[idx] * 1e3).astype(np.uint16)
        rows["current_battery"] = np.round(status.battery_current_a[idx] * 100).astype(np.int16)
        rows["battery_remaining"] = np.round(status.battery_remaining[idx] * 100).astype(np.int8)
        rows["errors_comm"] = status.errors_comm[idx]

    def _timesync(self, rows, idx, now_s, plant, status) -> None:
        rows["tc1"] = 0
        rows["ts1"] = int(now_s * 1e9)

    def _home_position(self, rows, idx, now_s, plant, status) -> None:
        home = status.home_ned_m[idx]
        lat, lon, alt = geodetic_of_ned(home, self.origin_lla)
        local = home - status.origin_ned_m[idx]
        rows["latitude"] = np.round(lat * 1e7)
        rows["longitude"] = np.round(lon * 1e7)
        rows["altitude"] = np.round(alt * 1e3)
        rows["x"], rows["y"], rows["z"] = local[:, 0], local[:, 1], local[:, 2]
        rows["q"] = np.array([1.0, 0.0, 0.0, 0.0])
        rows["time_usec"] = int(now_s * 1e6)

    def _gps_raw_int(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        lat, lon, alt = geodetic_of_ned(d["pos_ned"][idx], self.origin_lla)
        fill_gps_raw_int(rows, d["t_pos_us"][idx], lat, lon, alt, d["vel_ned"][idx])

    def _battery_status(self, rows, idx, now_s, plant, status) -> None:
        rows["current_consumed"] = np.round(plant.charge_used_c[idx] / 3.6).astype(np.int32)
        rows["energy_consumed"] = -1
        rows["temperature"] = 32767
        volts = np.full((idx.size, 10), 65535, dtype=np.uint16)
        volts[:, 0] = np.round(status.battery_voltage_v[idx] * 1e3).astype(np.uint16)
        rows["voltages"] = volts
        rows["current_battery"] = np.round(status.battery_current_a[idx] * 100).astype(np.int16)
        rows["battery_function"] = 1  # MAV_BATTERY_FUNCTION_ALL
        rows["type"] = 1  # MAV_BATTERY_TYPE_LIPO
        rows["battery_remaining"] = np.round(status.battery_remaining[idx] * 100).astype(np.int8)
        rows["charge_state"] = 1  # MAV_BATTERY_CHARGE_STATE_OK
