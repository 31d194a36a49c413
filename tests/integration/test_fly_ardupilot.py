"""`gcs fly` against ArduPilot Copters: the real `gcs` CLI as a subprocess and real
`vehicle-emu --autopilot ardupilot` processes (ArduCopter 4.7.0-dev SITL's protocol as recorded)
over 127.0.0.1 UDP.

What the ground station sees of each vehicle is the emulator's: its commands and their results
are the emulator's log lines, what it did with the setpoints is its ``--stats-json`` (per mode
they met, rejected by ArduPilot's rules, GUID_TIMEOUT expiries). Tests wait on the CLI's exit,
with timeouts; nothing sleeps to synchronise.

The copters run as SITL does: each sends from an ephemeral port (udpclient) and hears only the
address it sends to, so the team file's links learn their addresses (`learn_remote: true`, no
`remote_port`); they stream only a 1 Hz HEARTBEAT until `gcs fly` asks for every stream it needs
(EXTENDED_SYS_STATE included) with SET_MESSAGE_INTERVAL; no message-intervals file, no forced
bind. The vehicles boot at once (EMU_BOOT_SCALE=0) to keep the flights short; `gcs fly` waits for
a copter that is not ready yet (no position estimate, GUIDED not armable, ~41 s after a real
boot): test_fly_confirmed_ardupilot.py flies that.

The PARAM_REQUEST_READ retry test keeps a small scripted peer: it needs a vehicle that leaves the
first request unanswered, which no autopilot does on purpose.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink
from test_fly_confirmed import write_team

from gcs.link import VehicleLinkConfig, VehicleProxy
from gcs.link.vehicle_commands import ParamTimeoutError
from tests.harness import EmulatorProcess, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

ROOT = Path(__file__).resolve().parents[2]
GUIDED, LAND, BRAKE, GUIDED_NOGPS, STABILIZE = 4, 9, 17, 20, 0
FIX = "set GUID_OPTIONS bit 3 (8): otherwise ArduPilot reads thrust as a climb rate"
COMMAND_LINE = re.compile(r"command (\d+) \(([^)]*)\) -> (\w+)")


@contextlib.contextmanager
def copters(tmp: Path, gcs_ports: list[int], *guid_options: int
            ) -> Iterator[list[EmulatorProcess]]:
    """One `vehicle-emu --id N --autopilot ardupilot` per GUID_OPTIONS value, booted at once, on
    ArduPilot's ephemeral port, sending to ``gcs_ports[N-1]``; stats JSON at exit."""
    with contextlib.ExitStack() as stack:
        emus = []
        for k, g in enumerate(guid_options):
            log_dir = tmp / f"emu{k + 1}"
            log_dir.mkdir()
            emus.append(stack.enter_context(run_emulator(
                ["--id", str(k + 1), "--autopilot", "ardupilot", "--param", "EMU_BOOT_SCALE=0",
                 "--param", f"GUID_OPTIONS={g}", "--stats-json", str(tmp / f"emu{k + 1}.json")],
                remote_port=gcs_ports[k], log_dir=str(log_dir), bind=False)))
        yield emus


def team_file(tmp: Path, gcs_ports: list[int], remote_ports: list[int] | None = None) -> Path:
    """square4's vehicles 1 and 2 on one edge, rates mode, the GCS listening on ``gcs_ports``;
    the vehicles' addresses learned from their first message, or (``remote_ports``) fixed; the
    links of a loaded test machine (test_fly_confirmed.write_team)."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "ardupilot2"
    data["vehicles"] = data["vehicles"][:2]
    data["graph"]["edges"] = [[1, 2]]
    data["controller"]["mode"] = "rates"
    # the links and the modes are tested here, from where the takeoff leaves the copters; the
    # go-to-start in GUIDED is flown in test_fly_go_to_start.py and
    # test_fly_confirmed_ardupilot.py
    data["fly"]["go_to_start"] = {"enabled": False}
    for k, v in enumerate(data["vehicles"]):
        v["link"] = ({"local_port": gcs_ports[k], "learn_remote": True} if remote_ports is None
                     else {"local_port": gcs_ports[k], "remote_port": remote_ports[k]})
    return write_team(tmp / "team.yaml", data)


def fly(tmp: Path, gcs_ports: list[int], *args: str, remote_ports: list[int] | None = None
        ) -> tuple[int, str, str]:
    """`gcs fly` on the copters to its exit: (exit status, stdout, stderr)."""
    team = team_file(tmp, gcs_ports, remote_ports)
    proc = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team),
         "--out", str(tmp / "run"), "--no-figures", "--status", "off", "--log-level", "INFO",
         "--mode", "rates", *args],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONUNBUFFERED": "1"}, check=False)
    return proc.returncode, proc.stdout, proc.stderr


def sequence(emu: EmulatorProcess) -> list[tuple[str, float]]:
    """Mode changes, arming and take-off commands the copter received, from its log."""
    out = []
    for cmd, params, _ in COMMAND_LINE.findall(emu.log_text()):
        p = [float(x) for x in params.split(", ")]
        if cmd == "176":
            out.append(("mode", p[1]))
        elif cmd == "400":
            out.append(("arm" if p[0] == 1.0 else "disarm", p[1]))
        elif cmd in ("22", "21"):
            out.append(("takeoff" if cmd == "22" else "nav_land", p[6]))
    return out


def stats(tmp: Path, vehicle: int) -> dict[str, Any]:
    (summary,) = json.loads((tmp / f"emu{vehicle}.json").read_text())["by_vehicle"]
    return summary


def gcs_ports(n: int = 2) -> list[int]:
    return [free_udp_port() for _ in range(n)]


def sent_commands(tmp: Path) -> list[tuple[int, int, float]]:
    """(target sysid, command, param2) of every COMMAND_LONG gcs fly sent, from its tlog."""
    conn = mavutil.mavlink_connection(str(tmp / "run" / "flight.tlog"))
    out = []
    while (msg := conn.recv_match(type="COMMAND_LONG")) is not None:
        out.append((msg.target_system, msg.command, msg.param2))
    return out


def test_guid_options_without_bit_3_refuses_to_fly_and_never_arms(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground, vehicle 2 with GUID_OPTIONS at its default 0
    ports = gcs_ports()
    with copters(tmp_path, ports, 8, 0) as emus:
        started = time.monotonic()
        code, _, err = fly(tmp_path, ports)
        elapsed_s = time.monotonic() - started
    # THEN gcs fly refuses with one line naming vehicle 2 and the fix, and exits non-zero
    assert code == 1, err[-3000:]
    line = f"vehicle 2 (sysid 2): GUID_OPTIONS = 0 (bit mask 8 clear); {FIX}"
    assert f"gcs fly: ABORTED: {line} (exit 1)" in err.splitlines()
    # AND it read both values from the vehicles (ArduPilot casts integers to float)
    assert "vehicle 1: read_params ok: GUID_OPTIONS = 8" in err
    assert "vehicle 2: read_params ok: GUID_OPTIONS = 0" in err
    # AND neither was armed, changed mode (no LAND: they were disarmed on the ground) or got a
    # setpoint, and gcs fly did not wait for a landing (before: LAND, then up to 120 s)
    for k, emu in enumerate(emus, start=1):
        assert sequence(emu) == [], sequence(emu)
        s = stats(tmp_path, k)
        assert (s["mode"], s["armed"], s["setpoints_by_mode"]) == ("STABILIZE", False, {})
    # streams and the origin (REQUEST_MESSAGE 49), then PARAM_REQUEST_READs: reads only
    assert {c for _, c, _ in sent_commands(tmp_path)} <= {511, 512}
    # (measured 4 s on 2 cores, 25 s beside four other test flights and two compiles; a wait
    # for a landing took up to 120 s, and the LAND it needs is already refused above)
    assert elapsed_s < 60.0, elapsed_s


def test_ardupilot_takes_off_flies_guided_nogps_and_lands(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground with GUID_OPTIONS bit 3 set (72 = 64 + 8), as
    # SITL runs them: ephemeral ports, nothing but a 1 Hz HEARTBEAT streamed until asked
    ports = gcs_ports()
    with copters(tmp_path, ports, 8, 72) as emus:
        code, out, err = fly(tmp_path, ports, "--duration-s", "2")
    # THEN the flight completes and lands
    assert code == 0, err[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in out
    for k, emu in enumerate(emus, start=1):
        # GUIDED, arm, NAV_TAKEOFF 2.5 m above home, BRAKE, GUIDED_NOGPS, LAND (mode 9), each
        # accepted once (ArduPilot's one COMMAND_ACK)
        assert sequence(emu) == [("mode", 4.0), ("arm", 0.0), ("takeoff", 2.5), ("mode", 17.0),
                                 ("mode", 20.0), ("mode", 9.0)], sequence(emu)
        results = {r for c, _, r in COMMAND_LINE.findall(emu.log_text()) if c in ("176", "400", "22")}
        assert results == {"ACCEPTED"}
        # every stream request was accepted but the optional ODOMETRY-off one: ArduPilot has no
        # ap_message for ODOMETRY (nor TIMESYNC) and DENIES it; gcs fly does not use either
        streams = {(p.split(", ")[0], r) for c, p, r in COMMAND_LINE.findall(emu.log_text())
                   if c == "511"}
        assert {m for m, r in streams if r != "ACCEPTED"} == {"331"}, streams
        assert ("245", "ACCEPTED") in streams  # EXTENDED_SYS_STATE, asked for
        # AND the link stayed up from the first HEARTBEAT on (1 Hz until the streams came)
        assert "link lost" not in err
        s = stats(tmp_path, k)
        # LAND landed and disarmed it, and it stays in LAND (ArduPilot)
        assert (s["mode"], s["armed"]) == ("LAND", False)
        # every setpoint is one ArduPilot accepts (THROTTLE_IGNORE, a non-unit quaternion or
        # partial body rates would be rejected); priming met BRAKE (ignored there), none met
        # GUIDED; the law flew GUIDED_NOGPS, never long enough without one for GUID_TIMEOUT
        by_mode = s["setpoints_by_mode"]
        assert s["setpoints_rejected"] == 0
        assert by_mode.get("GUIDED", 0) == 0 and by_mode["BRAKE"] > 50
        # (a quarter of the 2 s formation's ticks at 100 Hz: on a busy machine the switch to
        # GUIDED_NOGPS is confirmed later, and the setpoints before it count under BRAKE)
        assert by_mode["GUIDED_NOGPS"] >= 0.25 * 2.0 * 100 and s["guided_timeouts"] == 0
        assert "Disarming motors" in emu.log_text()


def test_a_fixed_remote_port_misses_an_ephemeral_port_and_stops_at_once_commanding_nothing(
        tmp_path: Path) -> None:
    """Without `learn_remote` the commands go to the team file's remote_port, where nobody
    listens: preflight stops on the first stream request, named, and the copters (disarmed on
    the ground, landed state never received) get no LAND and are not waited for."""
    # GIVEN copters on their ephemeral ports and a team file with fixed remote ports
    ports = gcs_ports()
    with copters(tmp_path, ports, 8, 8) as emus:
        started = time.monotonic()
        code, _, err = fly(tmp_path, ports, "--duration-s", "1", "--connect-timeout-s", "20",
                           remote_ports=gcs_ports())
        elapsed_s = time.monotonic() - started
    assert "heard vehicle 1 (sysid 1)" in err and "heard vehicle 2 (sysid 2)" in err
    assert code == 1, err[-2000:]
    assert ("configure failed: vehicle 1 (sysid 1): stream ATTITUDE_QUATERNION (31) at 100 Hz: "
            "SET_MESSAGE_INTERVAL got no COMMAND_ACK in 3 attempts of 0.5 s") in err
    # THEN no command reached a vehicle, and gcs fly sent nothing but reads (the stream requests,
    # the origin's REQUEST_MESSAGE 49)
    assert all(sequence(e) == [] for e in emus)
    assert {c for _, c, _ in sent_commands(tmp_path)} <= {511, 512}
    assert "vehicle 1: land" not in err and "vehicle 2: land" not in err
    # (measured 4 s quiet, 22 s on a machine with four other flights, two compiles and two busy
    # loops; the LAND retries this is about are caught by the assertions above)
    assert elapsed_s < 60.0, elapsed_s


def test_a_vehicle_that_never_sends_is_named_in_one_line_and_the_other_is_not_commanded(
        tmp_path: Path) -> None:
    # GIVEN a learned link to vehicle 1 (running) and to vehicle 2 (never started): the GCS has
    # no address for vehicle 2 and can only wait to hear it
    ports = gcs_ports()
    with copters(tmp_path, ports, 8) as emus:
        code, _, err = fly(tmp_path, ports, "--connect-timeout-s", "5")
    # THEN it gives up after the connect timeout with one line for the silent vehicle
    assert code == 1, err[-2000:]
    assert (f"  vehicle 2 (sysid 2): nothing heard on udp 127.0.0.1:{ports[1]}; is it running, "
            "and does it send there?") in err.splitlines()
    assert "no link to 1 of 2 vehicles within 5 s (nothing was commanded)" in err
    # AND vehicle 1, heard, got nothing either
    assert sequence(emus[0]) == []
    assert sent_commands(tmp_path) == []


@dataclass
class ParamPeer(asyncio.DatagramProtocol):
    """Answers PARAM_REQUEST_READ for GUID_OPTIONS (as ArduPilot: INT32 cast to float), leaving
    the first ``drop`` requests unanswered; records every request."""

    drop: int = 0
    requests: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.mav = mavlink.MAVLink(None, 1, 1)
        self.transport: asyncio.DatagramTransport | None = None

    async def start(self) -> int:
        loop = asyncio.get_running_loop()
        self.transport, _ = await loop.create_datagram_endpoint(
            lambda: self, local_addr=("127.0.0.1", 0))
        return int(self.transport.get_extra_info("sockname")[1])

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:  # type: ignore[override]
        assert self.transport is not None
        for msg in self.mav.parse_buffer(data) or []:
            if msg.get_type() != "PARAM_REQUEST_READ":
                continue
            self.requests.append(msg.param_id)
            if len(self.requests) > self.drop and msg.param_id == "GUID_OPTIONS":
                reply = self.mav.param_value_encode(b"GUID_OPTIONS", 8.0, 6, 1, 0)
                self.transport.sendto(reply.pack(self.mav), addr)


def test_param_read_answers_retries_and_times_out_naming_vehicle_and_parameter() -> None:
    async def scenario() -> ParamPeer:
        # GIVEN a vehicle that leaves the first PARAM_REQUEST_READ unanswered
        peer = ParamPeer(drop=1)
        port = await peer.start()
        try:
            cfg = VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=0, remote_port=port)
            async with VehicleProxy(cfg) as proxy:
                # THEN the read is retried and returns the value
                assert await proxy.commands.param_read("GUID_OPTIONS", timeout_s=0.2, retries=2) == 8.0
                # AND a parameter nobody answers raises a TimeoutError naming both
                with pytest.raises(ParamTimeoutError, match=(
                        r"^vehicle 1 \(sysid 1\): PARAM_REQUEST_READ FS_GCS_ENABLE got no "
                        r"PARAM_VALUE in 2 attempts of 0\.05 s$")):
                    await proxy.commands.param_read("FS_GCS_ENABLE", timeout_s=0.05, retries=1)
                with pytest.raises(ValueError, match="1-16 ASCII characters"):
                    await proxy.commands.param_read("A_NAME_LONGER_THAN_16")
        finally:
            assert peer.transport is not None
            peer.transport.close()
        return peer

    peer = asyncio.run(scenario())
    assert peer.requests == ["GUID_OPTIONS", "GUID_OPTIONS", "FS_GCS_ENABLE", "FS_GCS_ENABLE"]
    assert issubclass(ParamTimeoutError, TimeoutError)
