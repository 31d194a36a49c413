"""Fuzz: >= 10,000 random and mutated datagrams at a running vehicle-emu; it keeps flying and
keeps answering valid commands correctly afterwards (issue 3, "bad input never kills it")."""

from __future__ import annotations

import math
import random
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import MavClient, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

N_PACKETS = 12_000


def _valid_frames(seed: int) -> list[bytes]:
    """Well-formed frames with hostile content, from a GCS sysid."""
    mav = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)
    nan, inf = math.nan, math.inf
    msgs = [
        mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 128, [1, 0, 0, 0], nan, 0, 0, 0.5),
        mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 0, [nan, 0, 0, 0], 0, 0, 0, 0.5),
        mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 0, [0, 0, 0, 0], 0, 0, 0, 0.5),
        mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 128, [1, 0, 0, 0], 1e9, 0, 0, 7.0),
        mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, 0, inf),
        mavlink.MAVLink_set_attitude_target_message(0, 9, 1, 128, [1, 0, 0, 0], 0, 0, 0, 0.5),
        mavlink.MAVLink_set_actuator_control_target_message(0, 0, 1, 1, [nan] * 8),
        mavlink.MAVLink_set_actuator_control_target_message(0, 3, 1, 1, [5.0] * 8),
        mavlink.MAVLink_command_long_message(9, 1, 400, 0, 0, 21196, 0, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, 176, 0, nan, inf, -inf, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, 511, 0, 1e30, -1e30, 0, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, 65535, 0, 0, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_param_set_message(1, 1, b"NOPE", 1.0, 9),
        mavlink.MAVLink_param_set_message(1, 1, b"COM_OF_LOSS_T", nan, 9),
        mavlink.MAVLink_param_request_read_message(1, 1, b"\xff\xfe", 30000),
        mavlink.MAVLink_set_mode_message(1, 0, 0xFFFFFFFF),
        mavlink.MAVLink_timesync_message(0, -5),
        mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
    ]
    return [m.pack(mav) for m in msgs]


def _packets(seed: int, n: int) -> list[bytes]:
    rng = random.Random(seed)
    frames = _valid_frames(seed)
    out: list[bytes] = []
    for k in range(n):
        kind = k % 6
        base = bytearray(rng.choice(frames))
        if kind == 0:  # pure garbage
            out.append(rng.randbytes(rng.randint(1, 300)))
        elif kind == 1:  # bit flips (mostly bad CRC)
            for _ in range(rng.randint(1, 4)):
                base[rng.randrange(len(base))] ^= 1 << rng.randrange(8)
            out.append(bytes(base))
        elif kind == 2:  # truncated
            out.append(bytes(base[: rng.randint(1, len(base) - 1)]))
        elif kind == 3:  # valid frames with hostile content, several per datagram
            out.append(b"".join(rng.choice(frames) for _ in range(rng.randint(1, 4))))
        elif kind == 4:  # a length byte that lies, then garbage
            base[1] = rng.randrange(256)
            out.append(bytes(base) + rng.randbytes(rng.randint(0, 40)))
        else:  # random message id with a plausible header (unknown ids), random payload
            hdr = bytes([0xFD, 20, 0, 0, 0, 245, 190]) + rng.randbytes(3)
            out.append(hdr + rng.randbytes(22))
    return out


def test_fuzz_does_not_kill_the_emulator_and_commands_still_work(tmp_path):
    port = free_udp_port()
    client = MavClient(port)
    # (noise off: PX4's hold wander, 0.35 m RMS, is test_emulator_hold_estimate's subject)
    with run_emulator(["--id", "1", "--in-air", "--param", "EMU_NOISE=0"], remote_port=port,
                      log_dir=str(tmp_path)) as emu:
        client.wait("HEARTBEAT", 60)
        z0 = -client.wait("LOCAL_POSITION_NED", 2).z
        packets = _packets(seed=3, n=N_PACKETS)
        assert len(packets) >= 10_000
        # GIVEN a flood of hostile datagrams from another socket on 127.0.0.1
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for i, data in enumerate(packets):
                sock.sendto(data, ("127.0.0.1", emu.bind_port))
                if i % 500 == 0:  # keep the loopback queue from overflowing
                    client.collect(0.01)
        client.collect(1.0)  # let it drain its receive queue
        # THEN it still answers valid commands correctly
        assert emu.proc.poll() is None
        assert client.command(400, 1) == 0  # already armed (in the air): ACCEPTED
        assert client.command(400, 0) == 2  # disarm in the air: DENIED
        # some fuzz setpoints are valid (clamped): once the newest is older than COM_OF_LOSS_T
        # (1 s), OFFBOARD is TEMPORARILY_REJECTED (after PX4 v1.16.0's first, ACCEPTED, ACK)
        client.collect(1.1)
        assert client.command_acks(176, 1 | 128, 6, 0, count=2) == [0, 1]
        assert client.get_param("COM_OF_LOSS_T").param_value == pytest.approx(1.0)
        # AND it kept flying (Hold) and reports the bad input
        status = client.wait("SYS_STATUS", 3)
        assert status.errors_comm > 1000
        client.wait("STATUSTEXT", 8, lambda m: m.text.startswith("Bad input"))
        assert abs(-client.wait("LOCAL_POSITION_NED", 2).z - z0) < 0.2
        hb = client.wait("HEARTBEAT", 3)
        assert hb.base_mode & 128 and hb.custom_mode == (4 << 16) | (3 << 24)
    assert emu.proc.returncode == 0
    assert "Traceback" not in emu.log_text()
    client.close()
