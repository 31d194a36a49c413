"""MAVLink telemetry log (.tlog) writer: per record, big-endian uint64 Unix us + raw packet."""

from __future__ import annotations

import logging
import struct
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

logger = logging.getLogger(__name__)

_TIMESTAMP = struct.Struct(">Q")
#: Write buffer; the file is written in chunks of this size, so the event loop rarely touches disk.
DEFAULT_BUFFER_BYTES = 256 * 1024


class TlogWriter:
    """Appends raw MAVLink packets (both directions, any vehicle) to a .tlog file.

    The format is the one QGroundControl writes and ``pymavlink.mavutil.mavlink_connection(path)``
    reads: per packet, the Unix time in microseconds as a big-endian uint64, then the packet bytes.
    Writes are buffered (``buffer_bytes``) and synchronous: ``write`` returns immediately unless a
    full buffer is flushed to disk. Lifetime: ``with TlogWriter(path) as tlog:``.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        wall_clock_s: Callable[[], float] = time.time,
        buffer_bytes: int = DEFAULT_BUFFER_BYTES,
    ) -> None:
        self.path = Path(path)
        self._wall_clock_s = wall_clock_s
        self._buffer_bytes = buffer_bytes
        self._file: BinaryIO | None = None
        self.records = 0
        self.bytes_written = 0
        self.write_errors = 0

    def open(self) -> None:
        """Create (truncate) the file; returns when it is open."""
        if self._file is not None:
            raise RuntimeError(f"tlog {self.path}: already open")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb", buffering=self._buffer_bytes)  # noqa: SIM115

    def close(self) -> None:
        """Flush and close; returns when done. Idempotent."""
        if self._file is not None:
            self._file.close()
            self._file = None
            logger.info("tlog %s: %d records, %d bytes", self.path, self.records,
                        self.bytes_written)

    def __enter__(self) -> TlogWriter:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        return self._file is not None

    def write(self, packet: bytes, unix_time_s: float | None = None) -> None:
        """Append one record (time defaults to the wall clock now); returns immediately.

        An OS error is counted (the first one logged), never raised: losing the log must not
        take the flight down. Writing to a closed writer raises RuntimeError.
        """
        t_s = self._wall_clock_s() if unix_time_s is None else unix_time_s
        self._append(_TIMESTAMP.pack(int(t_s * 1e6)) + packet, 1)

    def write_records(self, records: bytes, count: int) -> None:
        """Append ``count`` records already in the file's format (timestamp + packet each, as
        the hot path builds them); returns immediately, errors as :meth:`write`."""
        self._append(records, count)

    def _append(self, data: bytes, count: int) -> None:
        if self._file is None:
            raise RuntimeError(f"tlog {self.path}: write on a closed writer")
        try:
            self._file.write(data)
        except OSError as exc:
            if self.write_errors == 0:
                logger.error("tlog %s: write failed: %s", self.path, exc)
            self.write_errors += 1
            return
        self.records += count
        self.bytes_written += len(data)

    def flush(self) -> None:
        """Push buffered records to the OS; returns when done."""
        if self._file is not None:
            self._file.flush()
