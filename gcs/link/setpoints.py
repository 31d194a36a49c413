"""Setpoint encoders: one vehicle's checked, clamped, counted; the team's rates in one batch.

Frames: rates, torques and attitudes are in the paper's frames (ENU world, FLU body) and sent as
MAVLink's (NED, FRD); position targets alone are given in the vehicle's own local NED frame, as
sent. Every call returns immediately.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from gcs import frames
from gcs.link.codec import MavlinkCodec, MAVLinkMessage, SeqBlock
from gcs.link.config import VehicleLinkConfig
from gcs.link.fastpath import SET_ATTITUDE_TARGET_LEN, encode_set_attitude_target
from gcs.link.port import MavlinkPort
from gcs.link.tlog import TlogWriter
from gcs.link.udp import Address

TYPE_MASK_RATES_THRUST = 128  # ATTITUDE_IGNORE: body rates + thrust
TYPE_MASK_ATTITUDE_THRUST = 7  # roll/pitch/yaw rates ignored: attitude + thrust
#: SET_POSITION_TARGET_LOCAL_NED: acceleration (64, 128, 256) and yaw rate (2048) ignored:
#: position, velocity (the position loop's feed-forward) and yaw
TYPE_MASK_POSITION_VELOCITY_YAW = 64 | 128 | 256 | 2048
#: ... and with the acceleration as feed-forward too (position mode's slots): yaw rate ignored
TYPE_MASK_POSITION_VELOCITY_ACCELERATION_YAW = 2048
MAV_FRAME_LOCAL_NED = 1
#: q of rate setpoints: ignored (type_mask 128), but ArduPilot drops a non-unit one, so unit.
_IDENTITY_Q = (1.0, 0.0, 0.0, 0.0)
_TLOG_STAMP = struct.Struct(">Q")  # a tlog record's Unix time [us] (gcs.link.tlog)
#: What a `VehicleSetpoints` counts (fields of gcs.link.proxy.ProxyCounters).
SETPOINT_COUNTERS = ("setpoints_sent", "setpoints_rejected", "thrust_clamped", "torque_clamped")


class SetpointError(ValueError):
    """A setpoint with NaN/inf or the wrong shape; nothing was sent."""


class VehicleSetpoints:
    """One vehicle's setpoints, encoded with its link's ``codec`` and handed to ``send``: NaN/inf
    or a wrong shape raise SetpointError naming the vehicle (nothing sent, counted as
    ``setpoints_rejected``); thrust and torque outside their range are clamped and counted."""

    def __init__(self, name: str, config: VehicleLinkConfig, codec: MavlinkCodec,
                 send: Callable[[MAVLinkMessage], object],
                 time_boot_ms: Callable[[], int]) -> None:
        self._name = name
        self._sysid = config.sysid
        self._compid = config.compid
        self._codec = codec
        self._send = send
        self._time_boot_ms = time_boot_ms
        self._n = dict.fromkeys(SETPOINT_COUNTERS, 0)

    def counts(self) -> dict[str, int]:
        """The counters of `SETPOINT_COUNTERS`, by name."""
        return dict(self._n)

    def note_thrust_clamped(self) -> None:
        """A thrust this vehicle was sent in a team batch (`TeamSetpoints`) was clamped."""
        self._n["thrust_clamped"] += 1

    def note_sent(self) -> None:
        """A setpoint for this vehicle went out in a team batch (`TeamSetpoints`)."""
        self._n["setpoints_sent"] += 1

    def send_rates_thrust(self, rates_flu_radps: ArrayLike, thrust_norm: float) -> None:
        """SET_ATTITUDE_TARGET, type_mask 128: body rates (FLU, rad/s -> sent as FRD) and
        collective thrust (0..1, clamped and counted); returns immediately."""
        rates_frd = frames.frd_from_flu(self._finite(rates_flu_radps, (3,), "rates_flu_radps"))
        thrust = self._clamp(thrust_norm, 0.0, 1.0, "thrust_norm", "thrust_clamped")
        self._send(self._codec.mav.set_attitude_target_encode(
            self._time_boot_ms(), self._sysid, self._compid, TYPE_MASK_RATES_THRUST,
            _IDENTITY_Q, *(float(x) for x in rates_frd), thrust))
        self._n["setpoints_sent"] += 1

    def send_attitude_thrust(self, rotation_enu_flu: ArrayLike, thrust_norm: float) -> None:
        """SET_ATTITUDE_TARGET, type_mask 7: attitude R_enu_flu (FLU body in the ENU world; sent
        as the quaternion of R_ned_frd) and collective thrust (0..1, clamped and counted);
        returns immediately."""
        r = self._finite(rotation_enu_flu, (3, 3), "rotation_enu_flu")
        if not bool(frames.is_rotation(r, tol=1e-4)):
            self._n["setpoints_rejected"] += 1
            raise SetpointError(f"{self._name}: rotation_enu_flu is not a rotation matrix: {r}")
        q = frames.mavlink_quat_from_rotation_enu_flu(r)
        thrust = self._clamp(thrust_norm, 0.0, 1.0, "thrust_norm", "thrust_clamped")
        self._send(self._codec.mav.set_attitude_target_encode(
            self._time_boot_ms(), self._sysid, self._compid,
            TYPE_MASK_ATTITUDE_THRUST, [float(x) for x in q], 0.0, 0.0, 0.0, thrust))
        self._n["setpoints_sent"] += 1

    def send_position_target(self, position_enu_m: ArrayLike, velocity_enu_mps: ArrayLike,
                             yaw_enu_rad: float,
                             acceleration_enu_mps2: ArrayLike | None = None) -> None:
        """SET_POSITION_TARGET_LOCAL_NED, MAV_FRAME_LOCAL_NED: a target in the vehicle's own
        local frame (its EKF origin), given in ENU like every setpoint here and sent as NED:
        position [m], velocity feed-forward [m/s], yaw [rad, from east, anticlockwise] and, when
        given, acceleration feed-forward [m/s^2] (type_mask 2048: yaw rate ignored), else
        accelerations ignored too (type_mask 2496); returns immediately."""
        pos = frames.ned_from_enu(self._finite(position_enu_m, (3,), "position_enu_m"))
        vel = frames.ned_from_enu(self._finite(velocity_enu_mps, (3,), "velocity_enu_mps"))
        yaw = frames.yaw_ned_from_enu(self._finite(yaw_enu_rad, (), "yaw_enu_rad"))
        if acceleration_enu_mps2 is None:
            mask, acc = TYPE_MASK_POSITION_VELOCITY_YAW, np.zeros(3)
        else:
            mask = TYPE_MASK_POSITION_VELOCITY_ACCELERATION_YAW
            acc = frames.ned_from_enu(
                self._finite(acceleration_enu_mps2, (3,), "acceleration_enu_mps2"))
        self._send(self._codec.mav.set_position_target_local_ned_encode(
            self._time_boot_ms(), self._sysid, self._compid, MAV_FRAME_LOCAL_NED,
            mask, *(float(x) for x in pos), *(float(x) for x in vel),
            *(float(x) for x in acc), float(yaw), 0.0))
        self._n["setpoints_sent"] += 1

    def send_actuator_controls(self, torque_flu_norm: ArrayLike, thrust_norm: float) -> None:
        """SET_ACTUATOR_CONTROL_TARGET group 0: roll/pitch/yaw torque (FLU, -1..1 -> sent as FRD)
        and thrust (0..1), each clamped and counted; returns immediately. PX4 >= 1.14 ignores it."""
        torque = self._finite(torque_flu_norm, (3,), "torque_flu_norm")
        clipped = np.clip(torque, -1.0, 1.0)
        if np.any(clipped != torque):
            self._n["torque_clamped"] += 1
        torque_frd = frames.frd_from_flu(clipped)
        thrust = self._clamp(thrust_norm, 0.0, 1.0, "thrust_norm", "thrust_clamped")
        controls = [float(x) for x in torque_frd] + [thrust, 0.0, 0.0, 0.0, 0.0]
        self._send(self._codec.mav.set_actuator_control_target_encode(
            self._time_boot_ms() * 1000, 0, self._sysid, self._compid, controls))
        self._n["setpoints_sent"] += 1

    def _finite(self, value: ArrayLike, shape: tuple[int, ...], what: str) -> np.ndarray:
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            self._n["setpoints_rejected"] += 1
            raise SetpointError(f"{self._name}: {what}: expected finite shape {shape}, got {arr!r}")
        return arr

    def _clamp(self, value: float, low: float, high: float, what: str, counter: str) -> float:
        v = float(value)
        if not math.isfinite(v):
            self._n["setpoints_rejected"] += 1
            raise SetpointError(f"{self._name}: {what}: expected finite, got {v}")
        if v < low or v > high:
            self._n[counter] += 1
            return min(max(v, low), high)
        return v


class TeamMember(Protocol):
    """What `TeamSetpoints` uses of each vehicle's link (a `gcs.link.proxy.VehicleProxy`)."""

    @property
    def config(self) -> VehicleLinkConfig: ...

    @property
    def codec(self) -> MavlinkCodec:
        """Its sequence numbers and the ground station's ids."""
        ...

    @property
    def port(self) -> MavlinkPort: ...

    @property
    def tlog(self) -> TlogWriter | None: ...

    @property
    def setpoints(self) -> VehicleSetpoints: ...

    def now_s(self) -> float: ...

    def up_since_s(self) -> float:
        """When its link came up: time_boot_ms counts from there."""
        ...

    def batch_address(self) -> Address | None:
        """Where a packet for the vehicle goes now; None (not known yet) is counted."""
        ...


@dataclass(slots=True)
class _SendPlan:
    """What `TeamSetpoints` works out once per set of rows."""

    rows: list[int]
    idx: np.ndarray
    proxies: list[TeamMember]
    block: SeqBlock | None  # the links' shared sequence numbers (None: each its own)
    seq_rows: np.ndarray  # the links' rows in it
    tlog: TlogWriter | None  # the one tlog all of them write (None: each its own, or none)
    ports: list[tuple[MavlinkPort, list[int], list[TeamMember]]]  # positions in rows, proxies


class TeamSetpoints:
    """`VehicleSetpoints.send_rates_thrust` for many vehicles at once: one encode call
    (gcs.link.fastpath.encode_set_attitude_target), the sequence numbers in one numpy call when
    the links keep theirs in one block (the app's: its HotTable's), one ``sendto`` each. What does
    not change from tick to tick (ids, boot times, tlogs, who is sent what on which port) is
    worked out once per set of rows; every proxy must be `batch_sendable` (unsigned)."""

    def __init__(self, proxies: Sequence[TeamMember]) -> None:
        self.proxies = list(proxies)
        n = len(self.proxies)
        self._target_sys = np.array([p.config.sysid for p in self.proxies], dtype=np.int64)
        self._target_comp = np.array([p.config.compid for p in self.proxies], dtype=np.int64)
        # each link's boot, for time_boot_ms
        self._t0_s = np.array([p.up_since_s() for p in self.proxies])
        self._q = np.tile(np.array(_IDENTITY_Q), (n, 1))
        self._out = np.empty((n, 12 + SET_ATTITUDE_TARGET_LEN), dtype=np.uint8)
        self._lengths = np.empty(n, dtype=np.int64)
        self._plan: _SendPlan | None = None

    def _plan_for(self, rows: Sequence[int]) -> _SendPlan:
        plan = self._plan
        if plan is not None and plan.rows == rows:
            return plan
        rows = list(rows)
        if len(set(rows)) != len(rows):
            raise ValueError(f"TeamSetpoints: a row twice in {rows}")
        proxies = [self.proxies[i] for i in rows]
        blocks = [p.codec.seq_block for p in proxies]
        block = blocks[0][0]
        shared = all(b is block for b, _ in blocks)
        tlog = proxies[0].tlog
        by_port: dict[int, tuple[MavlinkPort, list[int]]] = {}
        for k, p in enumerate(proxies):
            by_port.setdefault(id(p.port), (p.port, []))[1].append(k)
        self._plan = plan = _SendPlan(
            rows, np.asarray(rows, dtype=np.int64), proxies,
            block if shared else None,
            np.array([r for _, r in blocks], dtype=np.int64),
            tlog if tlog is not None and all(p.tlog is tlog for p in proxies) else None,
            [(port, ks, [proxies[k] for k in ks]) for port, ks in by_port.values()])
        return plan

    def send_rates_thrust(self, rows: Sequence[int], rates_flu_radps: np.ndarray,
                          thrust_norm: np.ndarray) -> None:
        """Rows ``rows`` of rates (n, 3) FLU rad/s (sent as FRD) and thrust (n,) 0..1 (clamped
        and counted per vehicle) to those vehicles; returns immediately. Rows with NaN/inf must
        not be passed (send them one by one: `send_rates_thrust` raises `SetpointError` for
        each)."""
        if not rows:
            return
        plan = self._plan_for(rows)
        idx, proxies = plan.idx, plan.proxies
        rates_frd = frames.frd_from_flu(np.asarray(rates_flu_radps, dtype=np.float64)[idx])
        thrust = np.asarray(thrust_norm, dtype=np.float64)[idx]
        for k in np.flatnonzero((thrust < 0.0) | (thrust > 1.0)).tolist():
            proxies[k].setpoints.note_thrust_clamped()
        thrust = np.clip(thrust, 0.0, 1.0)
        if plan.block is not None:
            seq = plan.block.take(plan.seq_rows).astype(np.uint8)
        else:
            seq = np.array([p.codec.take_seq() for p in proxies], dtype=np.uint8)
        now_s = proxies[0].now_s()  # one clock for the team (the app's proxies share one)
        boot_ms = ((now_s - self._t0_s[idx]) * 1000.0).astype(np.int64) & 0xFFFFFFFF
        first = proxies[0].codec
        m = len(idx)
        out, lengths = self._out[:m], self._lengths[:m]
        encode_set_attitude_target(seq, first.src_system, first.src_component, boot_ms,
                                   self._target_sys[idx], self._target_comp[idx],
                                   TYPE_MASK_RATES_THRUST, self._q[:m], rates_frd, thrust, out,
                                   lengths)
        datagrams = [out[k, :size].tobytes() for k, size in enumerate(lengths.tolist())]
        if plan.tlog is not None:  # one block for the team
            stamp = _TLOG_STAMP.pack(int(time.time() * 1e6))
            plan.tlog.write_records(b"".join(stamp + d for d in datagrams), m)
        else:
            for p, data in zip(proxies, datagrams, strict=True):
                if p.tlog is not None:
                    p.tlog.write(data)
        for port, ks, members in plan.ports:
            addrs = [p.batch_address() for p in members]  # learned addresses may change
            for p in members:
                p.setpoints.note_sent()
            port.send_many([datagrams[k] for k in ks], addrs)
