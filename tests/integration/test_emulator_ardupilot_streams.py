"""The ardupilot personality's REQUEST_DATA_STREAM (msg 66), as ArduPilot's
handle_request_data_stream and ArduCopter's stream groups: real MAVProxy (its default stream
requests) and pymavlink's ``request_data_stream_send`` against a real `vehicle-emu --id 1
--autopilot ardupilot` on 127.0.0.1.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymavlink import mavutil

from tests.harness import MavClient, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
POSITION, EXTRA1 = mavutil.mavlink.MAV_DATA_STREAM_POSITION, mavutil.mavlink.MAV_DATA_STREAM_EXTRA1


@contextlib.contextmanager
def mavproxy(master_port: int, out_port: int, tmp: Path) -> Iterator[subprocess.Popen]:
    """`mavproxy.py --master udpin:... --out udp:... --daemon --non-interactive`, its state and
    tlog in ``tmp``; stopped on exit."""
    log = open(tmp / "mavproxy.log", "w")  # noqa: SIM115
    proc = subprocess.Popen(
        [sys.executable, str(MAVPROXY), "--master", f"udpin:127.0.0.1:{master_port}",
         "--out", f"udp:127.0.0.1:{out_port}", "--daemon", "--non-interactive",
         "--state-basedir", str(tmp)],
        stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
    try:
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
        log.close()


def rate_hz(client: MavClient, mtype: str, window_s: float) -> float:
    """Messages of ``mtype`` per second over ``window_s`` of receiving."""
    t0, n = time.monotonic(), 0
    while (left := t0 + window_s - time.monotonic()) > 0:
        m = client.recv(left)
        if m is not None and m.get_type() == mtype and m.get_srcSystem() == 1:
            n += 1
    return n / window_s


def test_mavproxy_shows_telemetry_from_its_default_stream_requests(tmp_path: Path) -> None:
    # GIVEN an ArduCopter vehicle (HEARTBEAT only until asked, as SITL) sending to MAVProxy,
    # and a pymavlink client on MAVProxy's --out port (the usual sim_vehicle.py set-up)
    master, client = free_udp_port(), MavClient(free_udp_port())
    try:
        with (run_emulator(["--id", "1", "--autopilot", "ardupilot"], remote_port=master,
                           log_dir=str(tmp_path), bind=False),
              mavproxy(master, client.port, tmp_path)):
            # WHEN MAVProxy asks for MAV_DATA_STREAM_ALL at its default --streamrate 4 (it does
            # so once it has seen the vehicle, then every 15 s)
            # THEN attitude, position and status reach the client through MAVProxy
            for mtype in ("ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS", "GPS_RAW_INT"):
                client.wait(mtype, 45)
            # AND at MAVProxy's 4 Hz (ArduPilot: every 1000 // 4 = 250 ms)
            assert rate_hz(client, "ATTITUDE", 5.0) == pytest.approx(4.0, abs=0.8)
    finally:
        client.close()


def test_request_data_stream_starts_and_stops_one_group_at_its_rate(tmp_path: Path) -> None:
    # GIVEN an ArduCopter vehicle talking to a pymavlink client
    client = MavClient(free_udp_port())
    try:
        with run_emulator(["--id", "1", "--autopilot", "ardupilot"], remote_port=client.port,
                          log_dir=str(tmp_path), bind=False):
            client.wait("HEARTBEAT", 60)
            # WHEN the client asks for the POSITION group at 10 Hz, as MAVProxy asks
            client.conn.mav.request_data_stream_send(1, 1, POSITION, 10, 1)
            # THEN GLOBAL_POSITION_INT comes at 10 Hz and EXTRA1's ATTITUDE not at all
            client.wait("GLOBAL_POSITION_INT", 5)
            assert rate_hz(client, "GLOBAL_POSITION_INT", 3.0) == pytest.approx(10.0, abs=1.5)
            assert client.seen("ATTITUDE") == []
            # WHEN POSITION is stopped (start_stop 0) and then EXTRA1 started at 5 Hz (loopback
            # keeps their order: the first ATTITUDE comes after the stop)
            client.conn.mav.request_data_stream_send(1, 1, POSITION, 10, 0)
            client.conn.mav.request_data_stream_send(1, 1, EXTRA1, 5, 1)
            client.wait("ATTITUDE", 5)
            client.history.clear()
            # THEN ATTITUDE comes at 5 Hz and GLOBAL_POSITION_INT no more
            assert rate_hz(client, "ATTITUDE", 3.0) == pytest.approx(5.0, abs=1.0)
            assert client.seen("GLOBAL_POSITION_INT") == []
    finally:
        client.close()
