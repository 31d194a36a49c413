"""MAVLink telemetry log (.tlog) writer: per record, big-endian uint64 Unix us + raw packet."""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

logger = logging.getLogger(__name__)

_TIMESTAMP = struct.Struct(">Q")
#: Records are handed to the writer thread in chunks of about this size.
DEFAULT_BUFFER_BYTES = 256 * 1024
#: Records waiting for the disk beyond this are dropped and counted (a disk stalled for tens of
#: seconds at 240 vehicles' 4.5 MB/s), so a slow disk never costs memory without bound.
MAX_PENDING_BYTES = 256 * 1024 * 1024
#: The writer thread writes what is pending at least this often [s].
WRITE_PERIOD_S = 0.25


class TlogWriter:
    """Appends raw MAVLink packets (both directions, any vehicle) to a .tlog file.

    The format is the one QGroundControl writes and ``pymavlink.mavutil.mavlink_connection(path)``
    reads: per packet, the Unix time in microseconds as a big-endian uint64, then the packet bytes.
    ``write`` only appends to memory and returns; a thread of the writer's own puts the records on
    disk (a chunk per ``buffer_bytes`` or per WRITE_PERIOD_S). A write to disk can block for
    hundreds of milliseconds (a journal commit on a busy disk, an SD card) and must not stop the
    control tick that logs its setpoints. What waits beyond MAX_PENDING_BYTES is dropped and
    counted (``dropped_records``, logged once). Lifetime: ``with TlogWriter(path) as tlog:``.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        wall_clock_s: Callable[[], float] = time.time,
        buffer_bytes: int = DEFAULT_BUFFER_BYTES,
        max_pending_bytes: int = MAX_PENDING_BYTES,
    ) -> None:
        self.path = Path(path)
        self._wall_clock_s = wall_clock_s
        self._buffer_bytes = buffer_bytes
        self._max_pending = max_pending_bytes
        self._file: BinaryIO | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._idle = threading.Event()  # set while nothing is pending or being written
        self._pending: list[bytes] = []
        self._pending_bytes = 0
        self._closing = False
        self.records = 0
        self.bytes_written = 0
        self.write_errors = 0
        self.dropped_records = 0

    def open(self) -> None:
        """Create (truncate) the file and start the writer thread; returns when it is open."""
        if self._file is not None:
            raise RuntimeError(f"tlog {self.path}: already open")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 (closed by close())
        self._closing = False
        self._idle.set()
        self._thread = threading.Thread(target=self._run, name=f"tlog {self.path.name}",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Write what is pending, stop the thread, close; returns when done. Idempotent."""
        if self._file is None:
            return
        self._closing = True
        self._wake.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self._file.close()
        self._file = None
        logger.info("tlog %s: %d records, %d bytes", self.path, self.records,
                    self.bytes_written)
        if self.dropped_records:
            logger.warning("tlog %s: %d records dropped (the disk fell behind)", self.path,
                           self.dropped_records)

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
        with self._lock:
            if self._pending_bytes + len(data) > self._max_pending:
                if self.dropped_records == 0:
                    logger.error("tlog %s: the disk fell %d MB behind: records are dropped "
                                 "(counted) until it catches up", self.path,
                                 self._pending_bytes >> 20)
                self.dropped_records += count
                return
            self._pending.append(data)
            self._pending_bytes += len(data)
            self._idle.clear()
            full = self._pending_bytes >= self._buffer_bytes
        self.records += count
        if full:
            self._wake.set()

    def flush(self) -> None:
        """Put everything written so far on disk; returns when done."""
        if self._file is None:
            return
        self._wake.set()
        self._idle.wait()

    def _run(self) -> None:
        """The writer thread: pending chunks to the file, until closed and drained."""
        file = self._file
        assert file is not None
        while True:
            self._wake.wait(WRITE_PERIOD_S)
            self._wake.clear()
            with self._lock:
                chunks, self._pending, self._pending_bytes = self._pending, [], 0
            if chunks:
                data = b"".join(chunks)
                try:
                    file.write(data)
                    file.flush()
                    self.bytes_written += len(data)
                except Exception as exc:  # noqa: BLE001 (counted: the log must not stop)
                    if self.write_errors == 0:
                        logger.error("tlog %s: write failed: %s", self.path, exc)
                    self.write_errors += 1
            with self._lock:
                if not self._pending:
                    self._idle.set()
            if self._closing and self._idle.is_set():
                return
