"""The .tlog writer produces files that pymavlink's log reader reads back message by message."""

from __future__ import annotations

import os
import struct
import threading
from pathlib import Path

import pytest
from pymavlink import mavutil

from gcs.link.codec import MavlinkCodec
from gcs.link.tlog import TlogWriter


def test_pymavlink_reads_back_every_record_with_its_time(tmp_path: Path) -> None:
    # GIVEN packets of both directions: a vehicle's telemetry and the GCS's commands
    vehicle, gcs = MavlinkCodec(1, 1), MavlinkCodec()
    packets = [
        vehicle.encode(vehicle.mav.heartbeat_encode(2, 12, 129, 393216, 4)),
        gcs.encode(gcs.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)),
        vehicle.encode(vehicle.mav.local_position_ned_encode(10, 1.0, 2.0, -3.0, 0, 0, 0)),
        vehicle.encode(vehicle.mav.command_ack_encode(400, 0, 0, 0, 255, 190)),
    ]
    t0_s = 1_700_000_000.0
    path = tmp_path / "flight" / "mav.tlog"
    # WHEN written at 10 ms intervals
    with TlogWriter(path) as tlog:
        for k, data in enumerate(packets):
            tlog.write(data, unix_time_s=t0_s + 0.01 * k)
    assert tlog.records == 4 and tlog.bytes_written == sum(8 + len(p) for p in packets)
    # THEN the file is big-endian microseconds + raw packet per record
    raw = path.read_bytes()
    assert struct.unpack(">Q", raw[:8])[0] == int(t0_s * 1e6)
    assert raw[8 : 8 + len(packets[0])] == packets[0]
    # AND pymavlink's reader returns the messages in order, with their timestamps
    log = mavutil.mavlink_connection(str(path))
    got = []
    while (msg := log.recv_msg()) is not None:
        got.append((msg.get_type(), msg.get_srcSystem(), round(msg._timestamp - t0_s, 6)))
    log.close()
    assert got == [("HEARTBEAT", 1, 0.0), ("COMMAND_LONG", 255, 0.01),
                   ("LOCAL_POSITION_NED", 1, 0.02), ("COMMAND_ACK", 1, 0.03)]


def test_default_time_is_the_injected_wall_clock(tmp_path: Path) -> None:
    with TlogWriter(tmp_path / "a.tlog", wall_clock_s=lambda: 12.5) as tlog:
        tlog.write(b"\xfd")
    assert (tmp_path / "a.tlog").read_bytes()[:8] == struct.pack(">Q", 12_500_000)


def test_write_after_close_raises(tmp_path: Path) -> None:
    tlog = TlogWriter(tmp_path / "b.tlog")
    with pytest.raises(RuntimeError, match=r"b\.tlog: write on a closed writer"):
        tlog.write(b"\xfd")


def _stalled_disk(tmp_path: Path):
    """A named pipe whose reader reads nothing until `go` is set: writes to it block once the
    pipe's buffer (64 KiB) is full, as a stalled disk does."""
    fifo = tmp_path / "stalled.tlog"
    os.mkfifo(fifo)
    go, got = threading.Event(), bytearray()

    def reader() -> None:
        with open(fifo, "rb") as f:
            go.wait(30.0)
            while chunk := f.read(65536):
                got.extend(chunk)

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    return fifo, go, got, thread


@pytest.mark.timeout(60)
def test_a_stalled_disk_does_not_block_the_writer_and_nothing_is_lost(tmp_path: Path) -> None:
    # GIVEN a tlog on a "disk" that takes nothing until released
    fifo, go, got, reader = _stalled_disk(tmp_path)
    record = struct.pack(">Q", 1) + bytes(range(200)) * 2  # 408 bytes
    with TlogWriter(fifo) as tlog:
        # WHEN 2 MB of records are written (the hot path's batches of 25)
        for _ in range(200):
            tlog.write_records(record * 25, 25)
        # THEN every call returned while the disk had taken at most its pipe's worth
        assert tlog.records == 5000 and not tlog.dropped_records
        assert tlog.bytes_written < 2_000_000
        go.set()  # the disk wakes up
    reader.join(10.0)
    # AND, closed, everything reached it, in order
    assert tlog.bytes_written == len(got) == 5000 * len(record)
    assert bytes(got) == record * 5000


@pytest.mark.timeout(60)
def test_what_a_stalled_disk_cannot_take_is_dropped_and_counted(tmp_path: Path) -> None:
    fifo, go, got, reader = _stalled_disk(tmp_path)
    record = struct.pack(">Q", 2) + b"\xfd" * 92  # 100 bytes
    # GIVEN at most 200 kB may wait for the disk
    with TlogWriter(fifo, buffer_bytes=10_000, max_pending_bytes=200_000) as tlog:
        # WHEN 1 MB is written while the disk is stalled
        for _ in range(10_000):
            tlog.write(record[8:], unix_time_s=2e-6)
        # THEN the records beyond what waits are dropped and counted, not queued without end
        assert tlog.dropped_records > 0
        assert tlog.records + tlog.dropped_records == 10_000
        go.set()
    reader.join(10.0)
    # AND what was kept reached the disk whole
    assert len(got) == tlog.records * 100 == tlog.bytes_written
    assert bytes(got) == record * tlog.records
