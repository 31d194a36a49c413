"""STATUSTEXT capture of one vehicle: severity, text and receive time, MAVLink 2 chunks joined.

Sans-IO: `StatusTextLog.feed(msg, rx_time_s)` takes each STATUSTEXT as received and returns the
completed text, if any. Odd input never raises: bytes that are not ASCII become U+FFFD, NULs end
the text, PX4's trailing TAB (v1.16.0 ends every text with one) and whitespace are stripped, an
unknown severity is kept as its number. MAVLink 2 splits a text longer than 50 bytes into chunks
with one nonzero `id` and `chunk_seq` 0, 1, ...; the last chunk is the one shorter than 50 bytes.
A text whose last chunk never comes is completed when a chunk of another id (or a text without
id) arrives, or after `CHUNK_TIMEOUT_S`, marked with `[...]` where chunks are missing.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

logger = logging.getLogger(__name__)

#: STATUSTEXT.text is char[50]; a chunk with fewer bytes is the last of its text.
CHUNK_BYTES = 50
#: A chunked text whose last chunk is this late is completed as it is.
CHUNK_TIMEOUT_S = 2.0
#: Texts kept per vehicle (the newest).
KEEP = 500


#: MAV_SEVERITY names from the MAVLink dialect: 'CRITICAL' for 2.
SEVERITY_NAMES = {k: v.name.removeprefix("MAV_SEVERITY_")
                  for k, v in mavlink.enums["MAV_SEVERITY"].items() if k < 8}
WARNING_SEVERITY, INFO_SEVERITY = 4, 6


@dataclass(frozen=True, slots=True)
class StatusText:
    """One text from the vehicle; `rx_time_s` on the GCS clock (its last chunk's arrival)."""

    severity: int
    text: str
    rx_time_s: float

    @property
    def severity_name(self) -> str:
        return SEVERITY_NAMES.get(self.severity, f"SEVERITY({self.severity})")

    def quoted(self) -> str:
        """`CRITICAL "Arming denied: Resolve system health failures first"`."""
        return f'{self.severity_name} "{self.text}"'


def _text_of(raw: object) -> tuple[str, int]:
    """(decoded text up to the first NUL, its length in bytes as sent)."""
    if isinstance(raw, bytes | bytearray):
        data = bytes(raw).split(b"\x00", 1)[0]
        return data.decode("ascii", errors="replace"), len(data)
    text = str(raw).split("\x00", 1)[0]
    return text, len(text.encode("utf-8", errors="replace"))


def _clean(text: str) -> str:
    return "".join(c if c.isprintable() else " " for c in text).strip()


def _log_level(severity: int) -> int:
    if severity <= WARNING_SEVERITY:
        return logging.WARNING
    return logging.INFO if severity <= INFO_SEVERITY else logging.DEBUG


@dataclass(slots=True)
class _Chunks:
    severity: int
    parts: dict[int, str]
    first_rx_s: float


class StatusTextLog:
    """Completed texts of one vehicle, newest last (at most `KEEP`); each is logged once with the
    vehicle's name, at WARNING for EMERGENCY..WARNING, INFO for NOTICE/INFO, DEBUG for DEBUG."""

    def __init__(self, name: str) -> None:
        self._name = name
        self._texts: deque[StatusText] = deque(maxlen=KEEP)
        self._chunks: dict[int, _Chunks] = {}
        self.count = 0

    def feed(self, msg: object, rx_time_s: float) -> StatusText | None:
        """A STATUSTEXT as received; returns the text it completed, if any (never raises)."""
        try:
            severity = int(getattr(msg, "severity", INFO_SEVERITY))
        except (TypeError, ValueError):
            severity = INFO_SEVERITY
        text, nbytes = _text_of(getattr(msg, "text", ""))
        try:
            text_id = int(getattr(msg, "id", 0) or 0)
            seq = int(getattr(msg, "chunk_seq", 0) or 0)
        except (TypeError, ValueError):
            text_id, seq = 0, 0
        done: StatusText | None = None
        for other in [k for k, c in self._chunks.items()
                      if k != text_id or rx_time_s - c.first_rx_s > CHUNK_TIMEOUT_S]:
            self._complete(other, rx_time_s)
        if text_id == 0:
            return self._add(severity, text, rx_time_s)
        chunks = self._chunks.setdefault(text_id, _Chunks(severity, {}, rx_time_s))
        chunks.parts[seq] = text
        if nbytes < CHUNK_BYTES:
            done = self._complete(text_id, rx_time_s)
        return done

    def _complete(self, text_id: int, rx_time_s: float) -> StatusText | None:
        chunks = self._chunks.pop(text_id)
        last = max(chunks.parts)
        text = "".join(chunks.parts.get(k, "[...]") for k in range(last + 1))
        return self._add(chunks.severity, text, rx_time_s)

    def _add(self, severity: int, text: str, rx_time_s: float) -> StatusText:
        entry = StatusText(severity, _clean(text), rx_time_s)
        self._texts.append(entry)
        self.count += 1
        logger.log(_log_level(severity), "%s: STATUSTEXT %s: %s", self._name,
                   entry.severity_name, entry.text)
        return entry

    def latest(self, since_s: float = -math.inf) -> StatusText | None:
        """The newest text received at or after `since_s` (GCS clock), else None."""
        if self._texts and self._texts[-1].rx_time_s >= since_s:
            return self._texts[-1]
        return None

    def texts(self) -> tuple[StatusText, ...]:
        """Every kept text, oldest first."""
        return tuple(self._texts)
