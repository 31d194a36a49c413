"""Sans-IO MAVLink 2 codec: bytes in -> messages out (bad frames counted), messages -> bytes."""

from __future__ import annotations

import hashlib
import logging
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

logger = logging.getLogger(__name__)

MAVLinkMessage = mavlink.MAVLink_message

STX_V1 = 0xFE
STX_V2 = 0xFD
HEADER_LEN_V1 = 6
HEADER_LEN_V2 = 10
CHECKSUM_LEN = 2
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
#: Seconds from the Unix epoch to the MAVLink signing epoch (2015-01-01T00:00:00Z).
SIGNING_EPOCH_UNIX_S = 1_420_070_400
#: A new signed stream is accepted up to one minute (in 10 us units) behind our timestamp.
SIGNING_NEW_STREAM_WINDOW_10US = 6_000_000

GCS_SYSID = 255
GCS_COMPID = 190  # MAV_COMP_ID_MISSIONPLANNER, the usual GCS component id


def signing_timestamp_10us(unix_time_s: float) -> int:
    """MAVLink signing timestamp (10 us units since 2015-01-01) of a Unix time in seconds."""
    return max(0, int((unix_time_s - SIGNING_EPOCH_UNIX_S) * 100_000))


class SeqBlock:
    """The outgoing sequence numbers and sent-message counts of several codecs, a row each, in
    two arrays: frames packed for many links at once (gcs.link.fastpath) take theirs in one
    numpy call. A codec made without one has a block of its own."""

    def __init__(self, n: int) -> None:
        self.seq = np.zeros(n, dtype=np.int64)
        self.sent = np.zeros(n, dtype=np.int64)

    def take(self, rows: np.ndarray) -> np.ndarray:
        """The next sequence number of each row (rows distinct), counted as sent."""
        seq = self.seq[rows]
        self.seq[rows] = (seq + 1) & 0xFF
        self.sent[rows] += 1
        return seq


@dataclass(frozen=True, slots=True)
class CodecStats:
    """Counters of one codec since creation."""

    bytes_in: int
    messages_in: int
    messages_out: int
    garbage_bytes: int  # bytes skipped while hunting for a start marker
    garbage_runs: int  # contiguous runs of such bytes
    bad_crc: int
    bad_length: int  # MAVLink 1 payload too long for its message id, or unknown incompat flags
    newer_fields: int  # MAVLink 2 payloads longer than our definition (extension fields of a
    #                    newer one, e.g. PX4 1.16's TIMESYNC targets): decoded without them
    truncated: int  # frame cut off at the end of a datagram
    unknown_id: int  # well-framed message whose id is not in the common dialect
    bad_signature: int  # signed frame whose signature does not match our key
    stale_signature: int  # good signature, timestamp not newer than the stream's last one
    unsigned_rejected: int  # unsigned frame on a link that requires signing
    other_errors: int  # pymavlink could not decode a well-framed, CRC-valid frame

    @property
    def errors(self) -> int:
        """Frames and garbage runs that yielded no message."""
        return (
            self.garbage_runs + self.bad_crc + self.bad_length + self.truncated + self.unknown_id
            + self.bad_signature + self.stale_signature + self.unsigned_rejected
            + self.other_errors
        )


class _ParserMAVLink(mavlink.MAVLink):
    """pymavlink parser whose signature check verifies the hash BEFORE trusting the timestamp.

    pymavlink's own ``check_signature`` records a stream's timestamp before checking the hash, so
    one forged packet with a far-future timestamp would lock the real sender out.
    """

    def __init__(self, src_system: int, src_component: int) -> None:
        super().__init__(None, srcSystem=src_system, srcComponent=src_component)
        self.last_reject = ""
        self.frame_signed = False

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:  # noqa: N803
        key = self.signing.secret_key
        assert key is not None
        if hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6] != bytes(msgbuf[-6:]):
            self.last_reject = "bad_signature"
            return False
        link_id = msgbuf[-13]
        t_low, t_high = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
        timestamp = t_low | (t_high << 32)
        stream = (link_id, srcSystem, srcComponent)
        last = self.signing.stream_timestamps.get(stream)
        if last is not None and timestamp <= last:
            self.last_reject = "stale_signature"
            return False
        if last is None and timestamp + SIGNING_NEW_STREAM_WINDOW_10US < self.signing.timestamp:
            self.last_reject = "stale_signature"
            return False
        self.signing.stream_timestamps[stream] = timestamp
        self.signing.timestamp = max(self.signing.timestamp, timestamp)
        return True


class MavlinkCodec:
    """One peer's MAVLink 2 parser and encoder (common dialect); no I/O, no clock but signing's.

    ``datagram_mode=True`` (UDP): each ``feed`` is one datagram; a frame cut off at its end is
    counted as ``truncated`` and dropped. ``False`` (byte streams): partial frames wait for more.
    """

    def __init__(
        self,
        src_system: int = GCS_SYSID,
        src_component: int = GCS_COMPID,
        *,
        datagram_mode: bool = True,
        wall_clock_s: Callable[[], float] = time.time,
        seqs: SeqBlock | None = None,
        seq_row: int = 0,
    ) -> None:
        self._mav = _ParserMAVLink(src_system, src_component)
        self._seqs = seqs if seqs is not None else SeqBlock(1)
        self._seq_row = seq_row if seqs is not None else 0
        self._datagram_mode = datagram_mode
        self._wall_clock_s = wall_clock_s
        self._buf = bytearray()
        self._allow_unsigned = False
        self._counts: dict[str, int] = {f.name: 0 for f in fields(CodecStats)
                                        if f.name != "messages_out"}  # that one: the SeqBlock

    # --- properties ------------------------------------------------------------------------------

    @property
    def mav(self) -> mavlink.MAVLink:
        """The pymavlink object, for its ``*_encode`` factories (do not call its ``send``)."""
        return self._mav

    @property
    def src_system(self) -> int:
        return int(self._mav.srcSystem)

    @property
    def src_component(self) -> int:
        return int(self._mav.srcComponent)

    @property
    def signing_enabled(self) -> bool:
        return self._mav.signing.secret_key is not None

    @property
    def seq_block(self) -> tuple[SeqBlock, int]:
        """Where this codec's outgoing sequence number lives: (block, row)."""
        return self._seqs, self._seq_row

    def stats(self) -> CodecStats:
        """A snapshot of the counters."""
        return CodecStats(**self._counts, messages_out=int(self._seqs.sent[self._seq_row]))

    # --- signing ---------------------------------------------------------------------------------

    def setup_signing(
        self,
        secret_key: bytes,
        *,
        link_id: int = 0,
        sign_outgoing: bool = True,
        allow_unsigned: bool = False,
        initial_timestamp_10us: int | None = None,
    ) -> None:
        """Enable MAVLink 2 signing on this link (32-byte key); returns immediately.

        Incoming: signed frames must carry a valid signature and a timestamp newer than the last
        one of their (link_id, sysid, compid) stream; unsigned frames are rejected unless
        ``allow_unsigned``. Outgoing (if ``sign_outgoing``): frames are signed with ``link_id``
        and a timestamp that never goes backwards and tracks the wall clock.
        """
        if not isinstance(secret_key, bytes | bytearray) or len(secret_key) != 32:
            got = len(secret_key) if isinstance(secret_key, bytes | bytearray) else type(secret_key)
            raise ValueError(f"signing secret_key: expected 32 bytes, got {got}")
        if not 0 <= link_id <= 255:
            raise ValueError(f"signing link_id: expected 0..255, got {link_id}")
        signing = self._mav.signing
        signing.secret_key = bytes(secret_key)
        signing.link_id = link_id
        signing.sign_outgoing = sign_outgoing
        signing.timestamp = (
            signing_timestamp_10us(self._wall_clock_s())
            if initial_timestamp_10us is None
            else initial_timestamp_10us
        )
        self._allow_unsigned = allow_unsigned
        # pymavlink asks this callback about unsigned frames and failed signatures alike; accept
        # only genuinely unsigned frames, and only if allowed.
        signing.allow_unsigned_callback = self._accept_unsigned

    def _accept_unsigned(self, _mav: mavlink.MAVLink, _msg_id: int) -> bool:
        return self._allow_unsigned and not self._mav.frame_signed

    # --- encode ----------------------------------------------------------------------------------

    def encode(self, msg: MAVLinkMessage) -> bytes:
        """Pack a message with this codec's sysid/compid and next sequence number (signed if on)."""
        signing = self._mav.signing
        if signing.sign_outgoing:
            signing.timestamp = max(signing.timestamp, signing_timestamp_10us(self._wall_clock_s()))
        seqs, row = self._seqs, self._seq_row
        self._mav.seq = int(seqs.seq[row])
        data = msg.pack(self._mav)
        seqs.seq[row] = (self._mav.seq + 1) & 0xFF
        seqs.sent[row] += 1
        return data

    def take_seq(self) -> int:
        """The next sequence number, for a frame packed elsewhere (gcs.link.fastpath) with this
        codec's ids; counted as sent. Unsigned links only: ValueError when signing is on."""
        if self._mav.signing.sign_outgoing:
            raise ValueError("take_seq: this link signs its frames; encode() them instead")
        return int(self._seqs.take(self._seq_row))

    # --- decode ----------------------------------------------------------------------------------

    def feed(self, data: bytes) -> list[MAVLinkMessage]:
        """Parse bytes, return the decoded messages in order; bad input is counted, never raised."""
        self._counts["bytes_in"] += len(data)
        buf = self._buf
        buf.extend(data)
        out: list[MAVLinkMessage] = []
        pos = 0
        n = len(buf)
        while pos < n:
            stx = buf[pos]
            if stx != STX_V2 and stx != STX_V1:
                nxt = _next_marker(buf, pos + 1)
                self._counts["garbage_bytes"] += nxt - pos
                self._counts["garbage_runs"] += 1
                pos = nxt
                continue
            header_len = HEADER_LEN_V2 if stx == STX_V2 else HEADER_LEN_V1
            if n - pos < 3:
                break
            payload_len = buf[pos + 1]
            signed = stx == STX_V2 and bool(buf[pos + 2] & IFLAG_SIGNED)
            frame_len = header_len + payload_len + CHECKSUM_LEN + (SIGNATURE_LEN if signed else 0)
            if n - pos < frame_len:
                break
            frame = buf[pos : pos + frame_len]
            pos += frame_len
            msg = self._decode_frame(frame, signed)
            if msg is not None:
                out.append(msg)
        if self._datagram_mode and pos < n:
            self._counts["truncated"] += 1
            pos = n
        del buf[:pos]
        self._counts["messages_in"] += len(out)
        return out

    def _decode_frame(self, frame: bytearray, signed: bool) -> MAVLinkMessage | None:
        if frame[0] == STX_V2:
            if frame[2] & ~IFLAG_SIGNED:
                self._counts["bad_length"] += 1  # unknown incompat flag: cannot frame it safely
                return None
            msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
            payload_len = frame[1]
        else:
            msg_id = frame[5]
            payload_len = frame[1]
        msg_type = mavlink.mavlink_map.get(msg_id)
        if msg_type is not None and payload_len > msg_type.unpacker.size:
            if frame[0] != STX_V2:
                self._counts["bad_length"] += 1
                return None
            # MAVLink 2 appends fields to a message as extensions: a sender with a newer
            # definition sends more bytes (its CRC covers them); a receiver reads what it knows
            newer = True
        else:
            newer = False
        self._mav.frame_signed = signed
        self._mav.last_reject = ""
        try:
            msg = self._mav.decode(frame)
        except mavlink.MAVError as exc:
            self._count_error(str(exc.message), signed)
            return None
        if isinstance(msg, mavlink.MAVLink_unknown):
            self._counts["unknown_id"] += 1
            return None
        if newer:
            self._counts["newer_fields"] += 1
        return msg

    def _count_error(self, reason: str, signed: bool) -> None:
        if "CRC" in reason:
            self._counts["bad_crc"] += 1
        elif "signature" in reason:
            if not signed:
                self._counts["unsigned_rejected"] += 1
            elif self._mav.last_reject == "stale_signature":
                self._counts["stale_signature"] += 1
            else:
                self._counts["bad_signature"] += 1
        elif "length" in reason:
            self._counts["bad_length"] += 1
        else:
            logger.debug("undecodable MAVLink frame: %s", reason)
            self._counts["other_errors"] += 1


def message_name(msg_id: int) -> str:
    """'EXTENDED_SYS_STATE (245)' for a common-dialect id, 'message 12345' otherwise."""
    msg_type = mavlink.mavlink_map.get(msg_id)
    return f"{msg_type.msgname} ({msg_id})" if msg_type is not None else f"message {msg_id}"


def _next_marker(buf: bytearray, start: int) -> int:
    """Index of the next MAVLink start marker at or after start, or len(buf)."""
    candidates = [i for i in (buf.find(STX_V2, start), buf.find(STX_V1, start)) if i >= 0]
    return min(candidates) if candidates else len(buf)
