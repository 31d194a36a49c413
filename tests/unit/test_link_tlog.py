"""The .tlog writer produces files that pymavlink's log reader reads back message by message."""

from __future__ import annotations

import struct
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
