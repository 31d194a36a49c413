"""The hot path of the link: the messages the law reads every tick, framed, CRC-checked and decoded
in batch straight into the team's arrays, and the team's setpoints encoded in one call.

A flight of hundreds of vehicles receives tens of thousands of MAVLink messages a second, most of
them the three the tick reads (LOCAL_POSITION_NED, ATTITUDE_QUATERNION, HIGHRES_IMU). Decoding each
into a pymavlink object costs tens of microseconds; here one numba call walks a whole batch of
datagrams (:func:`scan`) and writes those three into a `HotTable`, one row per vehicle (a slot),
with their receive times, counts, rates, the vehicle's sequence numbers and the frames themselves
(for the tlog and for a lazy pymavlink decode when someone asks for the message). Every other
frame, and every frame the kernel does not accept as one of a known vehicle's (unknown sysid,
another component, a stranger's address, an address not learned yet, a signed link, a bad CRC,
an unknown id, a frame cut off), is handed back as a byte range to the per-vehicle pymavlink path,
which counts and reports it as before. Sans-IO: bytes and times in, arrays out.

The rules the kernel applies are the proxy's (gcs.link.proxy): MAVLink 2 only (a MAVLink 1 frame
goes the slow way), incompat flags 0 (signed links go the slow way: the signature is checked by
the codec), the vehicle's sysid and compid, and its address once learned (or any address for a
fixed remote). The sequence numbers of every frame the kernel accepts, hot or not, are counted in
the table (`SequenceTracker` semantics), so the slow path skips them for those frames.

A `HotRow` reads one vehicle's row as telemetry (its proxy merges that with the slow path's).

Encoding: :func:`encode_set_attitude_target` packs SET_ATTITUDE_TARGET for the whole team into one
array (MAVLink 2, payload zeros trimmed as pymavlink does), each row with its own sequence number.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba import njit
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.codec import SeqBlock
from gcs.link.telemetry import (  # the rate estimate: the cache's, per message
    RATE_CLIP,
    RATE_EWMA_ALPHA,
    Received,
    SequenceStats,
    TypeStats,
    rate_of,
)

#: The hot messages, decoded into the table's value arrays, in table order (columns of the
#: rx/count/raw arrays).
HOT_NAMES = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "HIGHRES_IMU")
LPN, ATTQ, IMU = 0, 1, 2
#: Messages read now and then (preflight, the mission machine, the hover thrust) but streamed at
#: several Hz by every vehicle: kept as their latest frame (decoded by pymavlink only when asked
#: for, see `VehicleProxy.latest`), with counts and receive times. TIMESYNC: only the vehicle's
#: own requests (tc1 = 0), which the ground station does not answer; replies take the slow path.
LAZY_NAMES = ("ATTITUDE_TARGET", "GLOBAL_POSITION_INT", "SYS_STATUS", "EXTENDED_SYS_STATE",
              "BATTERY_STATUS", "TIMESYNC")
TABLE_NAMES = HOT_NAMES + LAZY_NAMES
_COLUMN = {name: k for k, name in enumerate(TABLE_NAMES)}
ATTITUDE_TARGET, GLOBAL_POSITION_INT, SYS_STATUS, EXTENDED_SYS_STATE = 3, 4, 5, 6
_TIMESYNC = len(TABLE_NAMES) - 1
#: The few fields of the lazy messages the mission machine reads at every check (`misc`
#: columns): EXTENDED_SYS_STATE landed_state, SYS_STATUS onboard_control_sensors_present and
#: _health, GLOBAL_POSITION_INT relative_alt [m], ATTITUDE_TARGET thrust.
LANDED_STATE, SENSORS_PRESENT, SENSORS_HEALTH, RELATIVE_ALT_M, TARGET_THRUST = 0, 1, 2, 3, 4
#: Values kept per hot message: LOCAL_POSITION_NED t_boot [s], x, y, z, vx, vy, vz (NED);
#: ATTITUDE_QUATERNION t_boot [s], q1..q4, roll/pitch/yaw speed (FRD); HIGHRES_IMU time_usec [s],
#: xacc, yacc, zacc (FRD).
LPN_FIELDS, ATTQ_FIELDS, IMU_FIELDS = 7, 8, 4
MAX_FRAME = 280  # MAVLink 2: 10 header + 255 payload + 2 CRC + 13 signature
#: Per-slot sequence counters (SequenceStats order).
SEQ_RECEIVED, SEQ_LOST, SEQ_DUPLICATES, SEQ_REORDERED = 0, 1, 2, 3
#: addr_of_slot values: any address is the vehicle's (a fixed remote), not learned yet (slow).
ANY_ADDRESS, UNLEARNED = -2, -1
_SET_ATTITUDE_TARGET = mavlink.MAVLink_set_attitude_target_message
SET_ATTITUDE_TARGET_LEN = _SET_ATTITUDE_TARGET.unpacker.size


def crc_extra_table() -> np.ndarray:
    """CRC_EXTRA of every common-dialect message id (-1: not in the dialect)."""
    table = np.full(max(mavlink.mavlink_map) + 1, -1, dtype=np.int16)
    for msg_id, cls in mavlink.mavlink_map.items():
        table[msg_id] = cls.crc_extra
    return table


def kind_table() -> np.ndarray:
    """Column of TABLE_NAMES for every common-dialect message id (-1: the slow path's)."""
    table = np.full(max(mavlink.mavlink_map) + 1, -1, dtype=np.int64)
    by_name = {cls.msgname: msg_id for msg_id, cls in mavlink.mavlink_map.items()}
    for k, name in enumerate(TABLE_NAMES):
        table[by_name[name]] = k
    return table


@njit(cache=True)
def _x25(buf: np.ndarray, start: int, end: int, extra: int) -> int:
    crc = 0xFFFF
    for k in range(start, end + 1):
        b = np.int64(extra) if k == end else np.int64(buf[k])
        tmp = (b ^ (crc & 0xFF)) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


class Datagrams(NamedTuple):
    """One batch of received datagrams: datagram d is ``buf[offsets[d]:offsets[d] +
    lengths[d]]``, from address ``addr_codes[d]`` (the port's codes), received at
    ``rx_times[d]`` (GCS clock); ``wall_us``: the wall clock for the tlog's records."""

    buf: np.ndarray
    offsets: np.ndarray
    lengths: np.ndarray
    addr_codes: np.ndarray
    rx_times: np.ndarray
    wall_us: int


class Routing(NamedTuple):
    """Which slot a frame belongs to: ``slot_of_sysid`` (-1: no vehicle), each slot's compid and
    address code; the dialect's CRC extras and each message id's table column (`kind_table`)."""

    slot_of_sysid: np.ndarray
    compid_of_slot: np.ndarray
    addr_of_slot: np.ndarray
    crc_extra: np.ndarray
    kinds: np.ndarray


class TableArrays(NamedTuple):
    """The arrays of a `HotTable` that :func:`scan` fills (``HotTable.arrays``)."""

    lpn: np.ndarray
    attq: np.ndarray
    imu: np.ndarray
    misc: np.ndarray
    rx: np.ndarray
    count: np.ndarray
    interval: np.ndarray
    raw: np.ndarray
    rawlen: np.ndarray
    seq_last: np.ndarray
    seq: np.ndarray
    last_any: np.ndarray
    accepted: np.ndarray
    touched: np.ndarray
    clock: np.ndarray


@njit(cache=True)
def scan(batch, routing, table, tlog, slow):  # noqa: ANN001, PLR0915
    """Walk the datagrams of ``batch`` (`Datagrams`), each frame to its slot by ``routing``
    (`Routing`) into ``table`` (`TableArrays`); returns ``(n_slow, tlog_len, tlog_records)``.

    Accepted frames update the slot's sequence counters, ``last_any``, ``accepted``; hot ones
    also ``touched`` (the caller zeroes it), their values, ``rx``/``count``/``interval`` (rate
    EWMA), ``raw``/``rawlen`` (the frame),
    ``clock`` (per slot: least receive-minus-stamp offset and its stamp, newest stamp and its
    receive time, samples; the caller feeds the vehicle's clock filter and zeroes column 4) and
    the tlog records (big-endian uint64 ``wall_us`` + frame) appended to ``tlog``. ``slow``
    rows ``(datagram, start, end, seq_counted)``: byte ranges for the pymavlink path, frames
    merged while contiguous and alike. Slot values: ``slot_of_sysid`` -1 for no vehicle.
    """
    buf, offsets, lengths, addr_codes, rx_times, wall_us = batch
    slot_of_sysid, compid_of_slot, addr_of_slot, crc_extra, kinds = routing
    (lpn, attq, imu, misc, rx, count, interval, raw, rawlen, seq_last, seq, last_any, accepted,
     touched, clock) = table
    n_slow = 0
    t_len = 0
    n_hot = 0
    pl = np.zeros(256, dtype=np.uint8)
    f32 = pl.view(np.float32)
    u32 = pl.view(np.uint32)
    u64 = pl.view(np.uint64)
    i32 = pl.view(np.int32)
    for d in range(offsets.shape[0]):
        pos = offsets[d]
        end = pos + lengths[d]
        rx_s = rx_times[d]
        while pos < end:
            start = pos
            counted = 0
            ok = False
            size = end - pos
            if buf[pos] == 0xFD and end - pos >= 12:
                plen = np.int64(buf[pos + 1])
                size = 12 + plen
                if buf[pos + 2] != 0:  # signed or unknown flags: the codec's to judge
                    size = min(size + 13, end - pos) if buf[pos + 2] & 1 else end - pos
                elif size <= end - pos:
                    sysid = buf[pos + 5]
                    slot = slot_of_sysid[sysid]
                    msg_id = (np.int64(buf[pos + 7]) | (np.int64(buf[pos + 8]) << 8)
                              | (np.int64(buf[pos + 9]) << 16))
                    if (slot >= 0 and buf[pos + 6] == compid_of_slot[slot]
                            and (addr_of_slot[slot] == ANY_ADDRESS
                                 or addr_of_slot[slot] == addr_codes[d])
                            and msg_id < crc_extra.shape[0] and crc_extra[msg_id] >= 0):
                        crc = _x25(buf, pos + 1, pos + 10 + plen, crc_extra[msg_id])
                        if (np.int64(buf[pos + 10 + plen])
                                | (np.int64(buf[pos + 11 + plen]) << 8)) == crc:
                            counted = 1
                            # sequence (gcs.link.telemetry.SequenceTracker)
                            s = np.int64(buf[pos + 4])
                            seq[slot, SEQ_RECEIVED] += 1
                            if seq_last[slot] >= 0:
                                delta = (s - seq_last[slot]) % 256
                                if delta == 0:
                                    seq[slot, SEQ_DUPLICATES] += 1
                                elif delta < 128:
                                    seq[slot, SEQ_LOST] += delta - 1
                                    seq_last[slot] = s
                                else:
                                    seq[slot, SEQ_REORDERED] += 1
                                    if seq[slot, SEQ_LOST] > 0:
                                        seq[slot, SEQ_LOST] -= 1
                            else:
                                seq_last[slot] = s
                            accepted[slot] += 1
                            if rx_s > last_any[slot]:
                                last_any[slot] = rx_s
                            kind = kinds[msg_id]
                            if kind == _TIMESYNC:  # a reply (tc1 != 0) is the proxy's to time
                                for k in range(min(plen, 8)):
                                    if buf[pos + 10 + k] != 0:
                                        kind = -1
                            if kind >= 0:
                                ok = True
                                touched[slot] += 1
                                pl[:] = 0
                                for k in range(plen):
                                    pl[k] = buf[pos + 10 + k]
                                stamp = -1.0
                                if kind == EXTENDED_SYS_STATE:
                                    misc[slot, LANDED_STATE] = pl[1]
                                elif kind == SYS_STATUS:
                                    misc[slot, SENSORS_PRESENT] = u32[0]
                                    misc[slot, SENSORS_HEALTH] = u32[2]
                                elif kind == GLOBAL_POSITION_INT:
                                    misc[slot, RELATIVE_ALT_M] = i32[4] * 1e-3
                                elif kind == ATTITUDE_TARGET:
                                    misc[slot, TARGET_THRUST] = f32[8]
                                elif kind > IMU:
                                    pass  # kept as its frame only
                                elif kind == 0:
                                    stamp = u32[0] * 1e-3
                                    lpn[slot, 0] = stamp
                                    for k in range(6):
                                        lpn[slot, 1 + k] = f32[1 + k]
                                elif kind == 1:
                                    stamp = u32[0] * 1e-3
                                    attq[slot, 0] = stamp
                                    for k in range(7):
                                        attq[slot, 1 + k] = f32[1 + k]
                                elif kind == IMU:
                                    imu[slot, 0] = u64[0] * 1e-6
                                    for k in range(3):
                                        imu[slot, 1 + k] = f32[2 + k]
                                if count[slot, kind] > 0:
                                    dt = rx_s - rx[slot, kind]
                                    old = interval[slot, kind]
                                    # telemetry.next_interval
                                    if old != old:
                                        interval[slot, kind] = np.inf
                                    elif old == np.inf:
                                        interval[slot, kind] = dt
                                    else:
                                        interval[slot, kind] = old + RATE_EWMA_ALPHA * (
                                            min(dt, RATE_CLIP * old) - old)
                                rx[slot, kind] = rx_s
                                count[slot, kind] += 1
                                rawlen[slot, kind] = size
                                for k in range(size):
                                    raw[slot, kind, k] = buf[pos + k]
                                if stamp >= 0.0:
                                    o = rx_s - stamp
                                    if clock[slot, 4] == 0 or o < clock[slot, 0]:
                                        clock[slot, 0] = o
                                        clock[slot, 1] = stamp
                                    if clock[slot, 4] == 0 or stamp >= clock[slot, 2]:
                                        clock[slot, 2] = stamp
                                        clock[slot, 3] = rx_s
                                    clock[slot, 4] += 1
                                if t_len + 8 + size <= tlog.shape[0]:
                                    for k in range(8):
                                        tlog[t_len + k] = (wall_us >> (8 * (7 - k))) & 0xFF
                                    for k in range(size):
                                        tlog[t_len + 8 + k] = buf[pos + k]
                                    t_len += 8 + size
                                    n_hot += 1
                                else:
                                    ok = False  # no room: the slow path logs it
                                    counted = 1
                else:
                    size = end - pos  # cut off: the codec counts it
            elif buf[pos] != 0xFD:
                # MAVLink 1 or garbage: the rest of the datagram goes the slow way
                size = end - pos
            else:
                size = end - pos
            pos = start + size
            if not ok:
                if (n_slow > 0 and slow[n_slow - 1, 0] == d and slow[n_slow - 1, 2] == start
                        and slow[n_slow - 1, 3] == counted):
                    slow[n_slow - 1, 2] = pos
                elif n_slow < slow.shape[0]:
                    slow[n_slow, 0] = d
                    slow[n_slow, 1] = start
                    slow[n_slow, 2] = pos
                    slow[n_slow, 3] = counted
                    n_slow += 1
    return n_slow, t_len, n_hot


class HotTable:
    """The team's hot telemetry: one row (slot) per vehicle, filled by :func:`scan`; columns of
    the per-message arrays in TABLE_NAMES order.

    Values are as the vehicle sent them (NED/FRD, MAVLink units); `gcs.fly.telemetry` converts
    the team at once. ``rx_s`` is -inf and values NaN until the first message of a kind.
    """

    def __init__(self, n: int) -> None:
        self.n = n
        self.lpn = np.full((n, LPN_FIELDS), np.nan)
        self.attq = np.full((n, ATTQ_FIELDS), np.nan)
        self.imu = np.full((n, IMU_FIELDS), np.nan)
        self.misc = np.full((n, 5), np.nan)
        k = len(TABLE_NAMES)
        self.rx_s = np.full((n, k), -math.inf)
        self.count = np.zeros((n, k), dtype=np.int64)
        self.interval_s = np.full((n, k), np.nan)
        self.raw = np.zeros((n, k, MAX_FRAME), dtype=np.uint8)
        self.rawlen = np.zeros((n, k), dtype=np.int64)
        self.seq_last = np.full(n, -1, dtype=np.int64)
        self.seq = np.zeros((n, 4), dtype=np.int64)
        self.last_any_rx_s = np.full(n, -math.inf)
        self.accepted = np.zeros(n, dtype=np.int64)
        self.touched = np.zeros(n, dtype=np.int64)
        self.clock = np.zeros((n, 5))
        #: per slot: the vehicle's compid (-1: no hot path, e.g. a signed link) and its address's
        #: code on its port (ANY_ADDRESS for a fixed remote, UNLEARNED until learned)
        self.compid_of_slot = np.full(n, -1, dtype=np.int64)
        self.addr_of_slot = np.full(n, UNLEARNED, dtype=np.int64)
        #: the outgoing sequence numbers of the slots' links (their codecs keep theirs here)
        self.out = SeqBlock(n)
        #: each slot's clock filter's line (a, b, t_ref, least delay: gcs.link.clock), kept here
        #: by the filter so the team's stamps are mapped at once
        self.clock_line = np.full((n, 4), np.nan)
        #: the arrays :func:`scan` fills, by name (built once: they are only changed in place)
        self.arrays = TableArrays(self.lpn, self.attq, self.imu, self.misc, self.rx_s, self.count,
                                  self.interval_s, self.raw, self.rawlen, self.seq_last, self.seq,
                                  self.last_any_rx_s, self.accepted, self.touched, self.clock)

    def frame(self, slot: int, kind: int) -> bytes | None:
        """The latest frame of message ``kind`` (column) from ``slot`` (None: none yet)."""
        if self.count[slot, kind] == 0:
            return None
        return bytes(self.raw[slot, kind, : self.rawlen[slot, kind]])


class HotRow:
    """One vehicle's row (``slot``) of its port's `HotTable`, read as telemetry: the latest
    message of a table kind (decoded by pymavlink once per new frame), receive times, counts,
    rates and sequence statistics; the vehicle's proxy merges them with its own cache's.
    Binds the row to the vehicle: ``compid`` (-1: no hot path) and, with ``learn_remote``,
    no address until `learned`, else any address."""

    def __init__(self, table: HotTable, slot: int, *, compid: int, learn_remote: bool) -> None:
        self._table = table
        self._slot = slot
        self._decoded: dict[int, tuple[int, Received]] = {}
        self._parser = mavlink.MAVLink(None)
        table.compid_of_slot[slot] = compid
        table.addr_of_slot[slot] = UNLEARNED if learn_remote else ANY_ADDRESS

    def learned(self, addr_code: int) -> None:
        """The vehicle's address is learned (its code on the port): accept its frames from it."""
        self._table.addr_of_slot[self._slot] = addr_code

    def latest(self, kind: str) -> Received | None:
        """Latest message of type ``kind`` in the row (None: not a table kind, or none yet)."""
        k = _COLUMN.get(kind)
        if k is None:
            return None
        count = int(self._table.count[self._slot, k])
        if count == 0:
            return None
        done = self._decoded.get(k)
        if done is not None and done[0] == count:
            return done[1]
        frame = self._table.frame(self._slot, k)
        assert frame is not None
        got = Received(self._parser.decode(bytearray(frame)),
                       float(self._table.rx_s[self._slot, k]))
        self._decoded[k] = (count, got)
        return got

    def last_any_rx_s(self) -> float:
        return float(self._table.last_any_rx_s[self._slot])

    def accepted(self) -> int:
        """Messages the hot path accepted (hot or handed back)."""
        return int(self._table.accepted[self._slot])

    def rate_hz(self, kind: str) -> float | None:
        """Receive rate of ``kind`` in the row (None: not a table kind, or none yet)."""
        k = _COLUMN.get(kind)
        if k is None or self._table.count[self._slot, k] == 0:
            return None
        return rate_of(float(self._table.interval_s[self._slot, k]))

    def restart_rate(self, kind: str) -> None:
        """Measure ``kind``'s rate afresh (nothing for a kind not in the table)."""
        k = _COLUMN.get(kind)
        if k is not None:
            self._table.interval_s[self._slot, k] = math.nan

    def sequence_stats(self, slow: SequenceStats) -> SequenceStats:
        """``slow`` (the proxy's own tracker) plus the row's sequence counts."""
        hot = self._table.seq[self._slot]
        return SequenceStats(slow.received + int(hot[SEQ_RECEIVED]), slow.lost + int(hot[SEQ_LOST]),
                             slow.duplicates + int(hot[SEQ_DUPLICATES]),
                             slow.reordered + int(hot[SEQ_REORDERED]))

    def type_stats(self, slow: dict[str, TypeStats]) -> dict[str, TypeStats]:
        """``slow`` (the proxy's cache's) with the row's kinds merged in: counts added, the later
        receive time, the row's rate."""
        out = dict(slow)
        i, table = self._slot, self._table
        for k, kind in enumerate(TABLE_NAMES):
            count = int(table.count[i, k])
            if count == 0:
                continue
            rate = rate_of(float(table.interval_s[i, k]))
            last = float(table.rx_s[i, k])
            cached = slow.get(kind)
            if cached is not None:
                last = max(last, cached.last_rx_s)
                count += cached.count
            out[kind] = TypeStats(count, last, rate)
        return out

    def feed_clock(self, on_sample: Callable[[float, float], None]) -> None:
        """Give ``on_sample(t_vehicle_s, rx_s)`` the least-delayed and the newest stamp of the
        messages stored since the port's last notice (the table's clock reduction), in time
        order."""
        least_o, least_t, newest_t, newest_rx, samples = self._table.clock[self._slot].tolist()
        if samples > 0:
            if least_t < newest_t:
                on_sample(least_t, least_t + least_o)
            on_sample(newest_t, newest_rx)


@njit(cache=True)
def encode_set_attitude_target(seq, src_sys, src_comp, time_boot_ms, target_sys,  # noqa: ANN001
                               target_comp, type_mask, q, rates, thrust, out, lengths):
    """SET_ATTITUDE_TARGET frames (MAVLink 2, unsigned) for every row into ``out`` (n, 51) and
    ``lengths`` (n,): row i from ``seq[i]``, ``time_boot_ms[i]``, target ``target_sys[i]`` /
    ``target_comp[i]``, ``q[i]`` (w, x, y, z), body ``rates[i]`` (FRD rad/s), ``thrust[i]``;
    trailing zero bytes of the payload are trimmed (MAVLink 2; at least one byte is kept)."""
    pl = np.zeros(40, dtype=np.uint8)
    f32 = pl.view(np.float32)
    u32 = pl.view(np.uint32)
    for i in range(out.shape[0]):
        pl[:] = 0
        u32[0] = time_boot_ms[i]
        for k in range(4):
            f32[1 + k] = q[i, k]
        for k in range(3):
            f32[5 + k] = rates[i, k]
        f32[8] = thrust[i]
        pl[36] = target_sys[i]
        pl[37] = target_comp[i]
        pl[38] = type_mask
        plen = 39
        while plen > 1 and pl[plen - 1] == 0:
            plen -= 1
        out[i, 0] = 0xFD
        out[i, 1] = plen
        out[i, 2] = 0
        out[i, 3] = 0
        out[i, 4] = seq[i]
        out[i, 5] = src_sys
        out[i, 6] = src_comp
        out[i, 7] = 82
        out[i, 8] = 0
        out[i, 9] = 0
        for k in range(plen):
            out[i, 10 + k] = pl[k]
        crc = _x25(out[i], 1, 10 + plen, 49)
        out[i, 10 + plen] = crc & 0xFF
        out[i, 11 + plen] = crc >> 8
        lengths[i] = 12 + plen


def warm_up() -> None:
    """Compile (or load from numba's cache) both kernels on a throwaway frame, so the first
    batch of a flight does not stall the event loop (gcs.fly.tick's warm-up calls this)."""
    n = 1
    out = np.zeros((n, 12 + SET_ATTITUDE_TARGET_LEN), dtype=np.uint8)
    lengths = np.zeros(n, dtype=np.int64)
    encode_set_attitude_target(np.zeros(n, dtype=np.uint8), 255, 190, np.zeros(n, np.int64),
                               np.ones(n, np.int64), np.ones(n, np.int64), 128,
                               np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (n, 1)),
                               np.zeros((n, 3)), np.zeros(n), out, lengths)
    table = HotTable(n)
    slot_of_sysid = np.full(256, -1, dtype=np.int64)
    frame = out[0, : lengths[0]]
    batch = Datagrams(frame, np.zeros(1, np.int64), np.array([frame.shape[0]], np.int64),
                      np.zeros(1, np.int64), np.zeros(1), 0)
    routing = Routing(slot_of_sysid, table.compid_of_slot, table.addr_of_slot,
                      crc_extra_table(), kind_table())
    scan(batch, routing, table.arrays, np.zeros(64, np.uint8), np.zeros((4, 4), np.int64))
