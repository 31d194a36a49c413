"""Sans-IO MAVLink 2 codec: bytes in -> messages out (pymavlink), messages -> bytes out.

* ``PeerDecoder``: one pymavlink ``MAVLink(None)`` parser per peer address (robust parsing), with
  counters for every kind of rejected input; a parser error never escapes, it is counted and the
  parser is replaced.
* ``BatchEncoder``: frames one message type for many vehicles in one numba call from a numpy
  structured array laid out in wire order (trailing-zero truncation, table-driven X.25 CRC with
  CRC_EXTRA). This is what makes 100 vehicles x ~300 messages/s affordable on one core.
* ``GenericEncoder``: pymavlink's own ``pack`` for rare messages (ACKs, PARAM_VALUE, STATUSTEXT),
  sharing the per-vehicle sequence counter with the batch encoder.
* ``HotDecoder``: the receive side's batch: many datagrams' frames of the hot messages (the
  setpoint streams, HEARTBEAT) checked in one numba call (MAVLink 2 framing, CRC with
  CRC_EXTRA); a datagram made only of good hot frames becomes ``HotMessage``s (the field values
  pymavlink's ``decode`` gives, without its byte-by-byte parser); anything else (other
  messages, MAVLink 1, signing, a bad CRC, a partial frame) goes to ``PeerDecoder`` as before.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

import numpy as np
from numba import njit
from pymavlink.dialects.v20 import common as mavlink
from pymavlink.generator.mavcrc import x25crc

log = logging.getLogger(__name__)

__all__ = [
    "BatchEncoder",
    "DecodeStats",
    "GenericEncoder",
    "HOT_MESSAGES",
    "HotDecoder",
    "PeerDecoder",
    "mavlink",
    "wire_dtype",
]

MAX_PEERS = 8
# decoded in batch (HotDecoder): SET_ATTITUDE_TARGET, SET_POSITION_TARGET_LOCAL_NED, HEARTBEAT
HOT_MESSAGES = (
    mavlink.MAVLink_set_attitude_target_message,
    mavlink.MAVLink_set_position_target_local_ned_message,
    mavlink.MAVLink_heartbeat_message,
)

_TYPES = {
    "uint64_t": "<u8",
    "int64_t": "<i8",
    "uint32_t": "<u4",
    "int32_t": "<i4",
    "uint16_t": "<u2",
    "int16_t": "<i2",
    "uint8_t": "u1",
    "uint8_t_mavlink_version": "u1",
    "int8_t": "i1",
    "float": "<f4",
    "double": "<f8",
    "char": "S1",
}


# crc' = (crc >> 8) ^ T[(crc ^ b) & 0xFF] with T[x] = X25 step of byte x applied to 0x??00:
# the step depends only on (crc ^ b) & 0xFF, so T can be tabulated from crc = 0 as below.
def _x25_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for x in range(256):
        tmp = x & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        table[x] = ((tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return table


CRC_TABLE = _x25_table()


@njit(cache=True)
def frame_payload(payload, length, msgid, crc_extra, sysid, compid, seq, table, out, at):
    """Frame the first ``length`` bytes of ``payload`` into ``out[at:]`` (MAVLink 2, unsigned,
    trailing zero bytes trimmed as pymavlink trims them); returns the frame's length."""
    plen = length
    while plen > 1 and payload[plen - 1] == 0:
        plen -= 1
    out[at] = 0xFD
    out[at + 1] = plen
    out[at + 2] = 0
    out[at + 3] = 0
    out[at + 4] = seq
    out[at + 5] = sysid
    out[at + 6] = compid
    out[at + 7] = msgid & 0xFF
    out[at + 8] = (msgid >> 8) & 0xFF
    out[at + 9] = (msgid >> 16) & 0xFF
    for j in range(plen):
        out[at + 10 + j] = payload[j]
    crc = 0xFFFF
    for j in range(1, 10 + plen):
        crc = (crc >> 8) ^ table[(crc ^ out[at + j]) & 0xFF]
    crc = (crc >> 8) ^ table[(crc ^ crc_extra) & 0xFF]
    out[at + 10 + plen] = crc & 0xFF
    out[at + 11 + plen] = (crc >> 8) & 0xFF
    return 12 + plen


@njit(cache=True)
def _frame_rows(payload, msgid, crc_extra, sysid, compid, seq, rows_vehicle, table, out, out_len):
    """Frame each payload row into ``out`` (MAVLink 2, unsigned); bumps ``seq`` per vehicle."""
    k, length = payload.shape
    for r in range(k):
        v = rows_vehicle[r]
        out_len[r] = frame_payload(payload[r], length, msgid, crc_extra, sysid[v], compid,
                                   seq[v], table, out[r], 0)
        seq[v] = (seq[v] + 1) & 0xFF


def wire_dtype(msg_class: Any) -> np.dtype:
    """numpy structured dtype of a pymavlink message class's payload, fields in wire order."""
    types = dict(zip(msg_class.fieldnames, msg_class.fieldtypes, strict=True))
    fields = []
    for name, alen in zip(msg_class.ordered_fieldnames, msg_class.array_lengths, strict=True):
        t = _TYPES[types[name]]
        if t == "S1":
            fields.append((name, f"S{max(alen, 1)}"))
        elif alen:
            fields.append((name, t, (alen,)))
        else:
            fields.append((name, t))
    return np.dtype(fields)


class BatchEncoder:
    """Frames one message type for many vehicles at once."""

    def __init__(self, msg_class: Any, compid: int = 1) -> None:
        self.msg_class = msg_class
        self.dtype = wire_dtype(msg_class)
        self.msgid = int(msg_class.id)
        self.crc_extra = int(msg_class.crc_extra)
        self.compid = compid

    def empty(self, k: int) -> np.ndarray:
        """Zeroed payload rows to fill by field name."""
        return np.zeros(k, dtype=self.dtype)

    def encode(
        self, rows: np.ndarray, rows_vehicle: np.ndarray, sysid: np.ndarray, seq: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Frames (k, max_len) uint8 and their lengths (k,) for payload rows of vehicles
        ``rows_vehicle``; ``seq`` (per vehicle, uint8) is advanced."""
        k = rows.shape[0]
        payload = rows.view(np.uint8).reshape(k, self.dtype.itemsize)
        out = np.empty((k, self.dtype.itemsize + 12), dtype=np.uint8)
        out_len = np.empty(k, dtype=np.int64)
        _frame_rows(
            payload,
            self.msgid,
            self.crc_extra,
            sysid,
            self.compid,
            seq,
            rows_vehicle.astype(np.int64),
            CRC_TABLE,
            out,
            out_len,
        )
        return out, out_len


class GenericEncoder:
    """pymavlink packing for one vehicle, sharing ``seq[index]`` with the batch encoders."""

    def __init__(self, sysid: int, compid: int, seq: np.ndarray, index: int) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self._seq = seq
        self._index = index

    def pack(self, msg: Any) -> bytes:
        """MAVLink 2 frame of a pymavlink message object."""
        seq = int(self._seq[self._index])
        self.mav.seq = seq
        data = msg.pack(self.mav)  # pack() does not advance mav.seq (send() would)
        self._seq[self._index] = (seq + 1) & 0xFF
        return data

    def pack_newer(self, msg: Any, newer_fields: bytes) -> bytes:
        """MAVLink 2 frame of ``msg`` with ``newer_fields`` appended to its payload: the
        extension bytes of a newer definition of the message than this dialect's (a receiver
        that knows only the older one must read past them)."""
        payload = msg.unpacker.pack(*(getattr(msg, n) for n in msg.ordered_fieldnames))
        payload = (payload + newer_fields).rstrip(b"\x00") or b"\x00"
        seq = int(self._seq[self._index])
        self._seq[self._index] = (seq + 1) & 0xFF
        header = bytes((0xFD, len(payload), 0, 0, seq, self.mav.srcSystem, self.mav.srcComponent,
                        msg.id & 0xFF, (msg.id >> 8) & 0xFF, msg.id >> 16))
        crc = x25crc(header[1:] + payload)
        crc.accumulate(bytes((msg.crc_extra,)))
        return header + payload + crc.crc.to_bytes(2, "little")


@dataclass(slots=True)
class DecodeStats:
    """Counters of received input; every rejected byte or message lands in one of them."""

    datagrams: int = 0
    bytes: int = 0
    messages: int = 0
    bad_crc: int = 0
    bad_data: int = 0
    unknown_msgid: int = 0
    parser_errors: int = 0

    @property
    def rejected(self) -> int:
        """Everything that was not a usable message."""
        return self.bad_crc + self.bad_data + self.unknown_msgid + self.parser_errors


class PeerDecoder:
    """Bytes from any number of peers -> pymavlink messages; one parser per peer address."""

    def __init__(self) -> None:
        self.stats = DecodeStats()
        self._parsers: OrderedDict[Any, Any] = OrderedDict()

    @staticmethod
    def _new_parser() -> Any:
        mav = mavlink.MAVLink(None)
        mav.robust_parsing = True
        return mav

    def _parser(self, peer: Any) -> Any:
        mav = self._parsers.get(peer)
        if mav is None:
            if len(self._parsers) >= MAX_PEERS:
                self._parsers.popitem(last=False)
            mav = self._new_parser()
            self._parsers[peer] = mav
        else:
            self._parsers.move_to_end(peer)
        return mav

    def idle(self, peer: Any = None) -> bool:
        """No partial frame held for ``peer`` (its next datagram starts afresh)."""
        mav = self._parsers.get(peer)
        return mav is None or mav.buf_len() == 0

    def count_decoded(self, data: bytes, peer: Any, messages: int) -> None:
        """Account for a datagram decoded by ``HotDecoder`` (as ``feed`` would have)."""
        st = self.stats
        st.datagrams += 1
        st.bytes += len(data)
        st.messages += messages
        self._parser(peer)

    def feed(self, data: bytes, peer: Any = None) -> list[Any]:
        """Decode one datagram from ``peer``; returns the good messages, counts the rest."""
        st = self.stats
        st.datagrams += 1
        st.bytes += len(data)
        mav = self._parser(peer)
        try:
            msgs = mav.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises many types on hostile input
            st.parser_errors += 1
            log.debug("parser error from %s: %s", peer, exc)
            self._parsers[peer] = self._new_parser()
            return []
        good = []
        for m in msgs:
            t = m.get_type()
            if t == "BAD_DATA":
                reason = getattr(m, "reason", "")
                if "CRC" in reason.upper():
                    st.bad_crc += 1
                else:
                    st.bad_data += 1
            elif t.startswith("UNKNOWN"):
                st.unknown_msgid += 1
            else:
                st.messages += 1
                good.append(m)
        return good


@njit(cache=True)
def _scan_hot(buf, starts, ends, hot_ids, hot_crc_extra, hot_size, table, dg_hot, f_dgram,
              f_kind, f_off):
    """Frames of datagrams ``buf[starts[d]:ends[d]]``: ``dg_hot[d]`` when the datagram is one or
    more complete, unsigned MAVLink 2 frames of hot message types (``hot_ids``), each with a
    good CRC and a payload of 1..``hot_size`` bytes; their frames are listed (datagram, kind,
    offset of the frame). Returns the number of frames listed."""
    nf = 0
    for d in range(starts.shape[0]):
        pos = starts[d]
        end = ends[d]
        first = nf
        ok = pos < end
        while ok and pos < end:
            if end - pos < 12 or buf[pos] != 0xFD or buf[pos + 2] != 0:
                ok = False
                break
            plen = buf[pos + 1]
            msgid = buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)
            kind = -1
            for k in range(hot_ids.shape[0]):
                if hot_ids[k] == msgid:
                    kind = k
            if kind < 0 or plen == 0 or plen > hot_size[kind] or pos + 12 + plen > end:
                ok = False
                break
            crc = 0xFFFF
            for j in range(pos + 1, pos + 10 + plen):
                crc = (crc >> 8) ^ table[(crc ^ buf[j]) & 0xFF]
            crc = (crc >> 8) ^ table[(crc ^ hot_crc_extra[kind]) & 0xFF]
            if buf[pos + 10 + plen] != (crc & 0xFF) or buf[pos + 11 + plen] != (crc >> 8):
                ok = False
                break
            f_dgram[nf] = d
            f_kind[nf] = kind
            f_off[nf] = pos
            nf += 1
            pos += 12 + plen
        dg_hot[d] = ok
        if not ok:
            nf = first
    return nf


class HotDecoder:
    """Datagrams -> pymavlink messages for the hot message types, in one batch (module
    docstring); ``None`` for a datagram that needs the full parser."""

    def __init__(self, classes: tuple[Any, ...] = HOT_MESSAGES) -> None:
        self.classes = classes
        self.ids = np.array([int(c.id) for c in classes], dtype=np.int64)
        self.crc_extra = np.array([int(c.crc_extra) for c in classes], dtype=np.int64)
        self.size = np.array([int(c.unpacker.size) for c in classes], dtype=np.int64)
        self.hot = [_hot_class(c) for c in classes]

    def decode(self, datagrams: list[bytes]) -> list[list[Any] | None]:
        """Per datagram, its messages (all hot, all good) or None (use ``PeerDecoder``)."""
        n = len(datagrams)
        lengths = np.fromiter((len(d) for d in datagrams), dtype=np.int64, count=n)
        ends = np.cumsum(lengths)
        starts = ends - lengths
        blob = b"".join(datagrams)
        buf = np.frombuffer(blob, dtype=np.uint8)
        cap = int(ends[-1]) // 12 + 1 if n else 1
        dg_hot = np.zeros(n, dtype=np.bool_)
        f_dgram = np.empty(cap, dtype=np.int64)
        f_kind = np.empty(cap, dtype=np.int64)
        f_off = np.empty(cap, dtype=np.int64)
        nf = _scan_hot(buf, starts, ends, self.ids, self.crc_extra, self.size, CRC_TABLE,
                       dg_hot, f_dgram, f_kind, f_off)
        out: list[list[Any] | None] = [[] if h else None for h in dg_hot.tolist()]
        for d, k, off in zip(f_dgram[:nf].tolist(), f_kind[:nf].tolist(), f_off[:nf].tolist(),
                             strict=True):
            out[d].append(_message(self.hot[k], self.classes[k], blob, off))  # type: ignore[union-attr]
        return out


_ZEROS = bytes(256)


class HotMessage(tuple):
    """A decoded hot message: its fields by name, as pymavlink's message object has them
    (arrays as lists, declaration order), and the header accessors the handlers use
    (``get_type``, ``get_msgId``, ``get_srcSystem``, ``get_srcComponent``, ``get_seq``). A
    tuple, built in one step: a pymavlink object costs several times as much."""

    __slots__ = ()
    msgtype: Any = None
    fieldnames: tuple[str, ...] = ()

    def get_type(self) -> str:
        return str(self.msgtype.msgname)

    def get_msgId(self) -> int:  # noqa: N802 (pymavlink's name)
        return int(self.msgtype.id)

    def get_srcSystem(self) -> int:  # noqa: N802
        return int(self[-3])

    def get_srcComponent(self) -> int:  # noqa: N802
        return int(self[-2])

    def get_seq(self) -> int:
        return int(self[-1])

    def to_dict(self) -> dict[str, Any]:
        """As pymavlink's ``to_dict``."""
        return {"mavpackettype": self.get_type(),
                **dict(zip(self.fieldnames, self[: len(self.fieldnames)], strict=True))}

    def __repr__(self) -> str:
        return f"{self.get_type()} {self.to_dict()}"


def _hot_class(msgtype: Any) -> tuple[type[HotMessage], list[tuple[int, int]], bool]:
    """The HotMessage class of a pymavlink message class, where each declared field sits in
    the wire-order tuple its unpacker gives ((start, length): length 1 a scalar, and a char
    array, which unpacks to one bytes value), and whether it has strings."""
    names = tuple(msgtype.fieldnames)
    attrs: dict[str, Any] = {"__slots__": (), "msgtype": msgtype, "fieldnames": names}
    for j, name in enumerate(names):
        attrs[name] = property(itemgetter(j))
    cls = type(f"Hot_{msgtype.msgname}", (HotMessage,), attrs)
    types = dict(zip(msgtype.fieldnames, msgtype.fieldtypes, strict=True))
    plan = []
    for name, order in zip(names, msgtype.orders, strict=True):
        length = 1 if types[name] == "char" else msgtype.lengths[order]
        plan.append((sum(msgtype.lengths[:order]), length))
    return cls, plan, "char" in types.values()


def _message(hot: tuple[type[HotMessage], list[tuple[int, int]], bool], msgtype: Any,
             blob: bytes, off: int) -> HotMessage:
    """The message of the checked frame at ``blob[off:]``: the values pymavlink's
    ``MAVLink.decode`` gives (zero-padded payload, arrays as lists, strings without NULs)."""
    cls, plan, strings = hot
    plen = blob[off + 1]
    size = msgtype.unpacker.size
    payload = blob[off + 10 : off + 10 + plen]
    if plen < size:
        payload += _ZEROS[: size - plen]
    t = msgtype.unpacker.unpack(payload)
    values = [t[a] if n == 1 else list(t[a : a + n]) for a, n in plan]
    if strings:
        values = [v.rstrip(b"\x00") if isinstance(v, bytes) else v for v in values]
    values += (blob[off + 5], blob[off + 6], blob[off + 4])
    return tuple.__new__(cls, values)
