"""The three 100 Hz streams a ground station flies on, scheduled, built and framed in one
compiled pass over the fleet.

`gcs fly` asks every vehicle for ATTITUDE_QUATERNION, LOCAL_POSITION_NED and HIGHRES_IMU at
100 Hz. Through `Telemetry.collect`'s general path each of them costs some thirty numpy calls a
collect (its schedule, the vehicles it is due for, a payload row per vehicle, the framing):
at 240 vehicles and a collect every 2 ms that was half of the fleet's tick. `frame_streams`
does the same work per vehicle in one numba loop, from the quantities `Telemetry._derive`
computed for the collect, and leaves each vehicle's frames back to back in one row of ``out``,
its sequence numbers taken in that order. The field values are those of the general path's
builders (`Telemetry._attitude_quaternion`, `_local_position`, `_highres_imu`); the messages the
general path frames in the same collect follow them in the vehicle's datagram.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from vehicle_emulator.mavlink.codec import frame_payload, mavlink, wire_dtype

#: The streams, in the order their frames are written (a vehicle's datagram starts with them).
NAMES = ("ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "HIGHRES_IMU")
_CLASSES = (mavlink.MAVLink_attitude_quaternion_message,
            mavlink.MAVLink_local_position_ned_message,
            mavlink.MAVLink_highres_imu_message)
MSGIDS = np.array([c.id for c in _CLASSES], dtype=np.int64)
CRC_EXTRAS = np.array([c.crc_extra for c in _CLASSES], dtype=np.int64)
PAYLOAD_BYTES = np.array([wire_dtype(c).itemsize for c in _CLASSES], dtype=np.int64)
#: Bytes of one vehicle's frames of all three.
ROW_BYTES = int(PAYLOAD_BYTES.sum()) + 12 * len(NAMES)
_SCRATCH_BYTES = 64  # the largest payload (HIGHRES_IMU, 63 bytes), 8-byte aligned
_IMU_FIELDS = 0x3F | 0x200 | 0x800 | 0x1000  # acc, gyro, abs pressure, pressure alt, temperature


class Schedule(NamedTuple):
    """The telemetry schedule (vehicle x message: next due time and interval [s]), the three
    streams' columns of it, and the per-message sent counters."""

    next_due_s: np.ndarray
    interval_s: np.ndarray
    cols: np.ndarray
    sent: np.ndarray


class Senders(NamedTuple):
    """Per vehicle: its link is up, its system id and outgoing sequence number; the streams'
    component id."""

    enabled: np.ndarray
    sysid: np.ndarray
    compid: int
    seq: np.ndarray


class StreamValues(NamedTuple):
    """What the three streams carry, per vehicle (NED/FRD, MAVLink units; `Telemetry._derive`):
    attitude quaternion, body rates and their sample time; position (relative to the EKF
    origin), velocity, their sample time and the first one the estimator had a position at;
    specific force, the IMU's gyro and its sample time; the altitude (home altitude plus the
    height up) for the barometer fields."""

    q: np.ndarray
    w_frd_radps: np.ndarray
    t_att_ms: np.ndarray
    pos_ned_m: np.ndarray
    origin_ned_m: np.ndarray
    vel_ned_mps: np.ndarray
    t_pos_ms: np.ndarray
    position_from_ms: np.ndarray
    acc_frd_mps2: np.ndarray
    gyro_frd_radps: np.ndarray
    t_att_us: np.ndarray
    z_up_m: np.ndarray
    home_alt_m: float


@njit(cache=True)
def frame_streams(now_s, schedule, senders, values, table, out, out_len):
    """Per vehicle: each of the three streams (columns ``cols`` of the `Schedule`) that is due
    at ``now_s`` moves on one interval (to ``now_s`` + interval if that is not ahead, as the
    general path does) and, if the vehicle's link is up (`Senders`; and, for
    LOCAL_POSITION_NED, its estimator had a position at the sample), is framed from `values`
    (`StreamValues`) into ``out[i]`` with the CRC ``table``; ``out_len[i]`` is the bytes
    written, ``sent[cols[m]]`` counts them, ``seq`` advances per frame. Each bundle may come
    as a plain tuple of its fields, as Telemetry passes them (numba types those faster)."""
    next_due, interval, cols, sent = schedule
    enabled, sysid, compid, seq = senders
    (q, w_frd, t_att_ms, pos_ned, origin_ned, vel_ned, t_pos_ms, position_from_ms, acc_frd,
     gyro_frd, t_att_us, z_up, home_alt_m) = values
    scratch = np.zeros(_SCRATCH_BYTES, dtype=np.uint8)
    f4 = scratch.view(np.float32)
    u4 = scratch.view(np.uint32)
    u8 = scratch.view(np.uint64)
    u2 = scratch.view(np.uint16)
    n = next_due.shape[0]
    for i in range(n):
        at = 0
        for m in range(3):
            k = cols[m]
            if not next_due[i, k] <= now_s:
                continue
            nxt = next_due[i, k] + interval[i, k]
            next_due[i, k] = now_s + interval[i, k] if nxt <= now_s else nxt
            if not enabled[i]:
                continue
            if m == 1 and t_pos_ms[i] < position_from_ms[i]:
                continue
            scratch[:] = 0
            if m == 0:  # ATTITUDE_QUATERNION
                u4[0] = np.uint32(t_att_ms[i] & 0xFFFFFFFF)
                for j in range(4):
                    f4[1 + j] = q[i, j]
                for j in range(3):
                    f4[5 + j] = w_frd[i, j]
            elif m == 1:  # LOCAL_POSITION_NED, relative to the vehicle's EKF origin
                u4[0] = np.uint32(t_pos_ms[i] & 0xFFFFFFFF)
                for j in range(3):
                    f4[1 + j] = pos_ned[i, j] - origin_ned[i, j]
                    f4[4 + j] = vel_ned[i, j]
            else:  # HIGHRES_IMU
                u8[0] = np.uint64(t_att_us[i])
                for j in range(3):
                    f4[2 + j] = acc_frd[i, j]
                    f4[5 + j] = gyro_frd[i, j]
                alt = home_alt_m + z_up[i]
                f4[11] = 1013.25 * (1.0 - 2.25577e-5 * alt) ** 5.25588
                f4[13] = alt
                f4[14] = 25.0
                u2[30] = _IMU_FIELDS
            at += frame_payload(scratch, PAYLOAD_BYTES[m], MSGIDS[m], CRC_EXTRAS[m], sysid[i],
                                compid, seq[i], table, out[i], at)
            seq[i] = (seq[i] + 1) & 0xFF
            sent[k] += 1
        out_len[i] = at


@njit(cache=True)
def place_rows(out, out_len, buf, starts, cursor):
    """Copy vehicle i's ``out_len[i]`` bytes of ``out[i]`` to ``buf[starts[i]:]``; ``cursor[i]``
    is left just after them."""
    for i in range(out.shape[0]):
        s = starts[i]
        for j in range(out_len[i]):
            buf[s + j] = out[i, j]
        cursor[i] = s + out_len[i]
