"""`gcs fly` against ArduPilot Copters: the real `gcs` CLI as a subprocess and real
`vehicle-emu --autopilot ardupilot` processes (ArduCopter 4.7.0-dev SITL's protocol as recorded)
over 127.0.0.1 UDP.

What the ground station sees of each vehicle is the emulator's: its commands and their results
are the emulator's log lines, what it did with the setpoints is its ``--stats-json`` (per mode
they met, rejected by ArduPilot's rules, GUID_TIMEOUT expiries). Tests wait on the CLI's exit,
with timeouts; nothing sleeps to synchronise.

Where today's `gcs fly` cannot fly the faithful personality, the vehicles are configured around
it, and the first gap is pinned by a test of gcs fly's safe reaction to it:
* ArduPilot SITL sends from an ephemeral port (udpclient) and hears only the address it sends
  to; `gcs fly` answers the team file's `remote_port`. The flights force a bind (`--bind`), as a
  relay (the team's SITL flights used one) or ArduPilot's `udp:` serial option would.
* ArduCopter refuses to arm in GUIDED until its EKF uses GPS (~41 s after boot) and `gcs fly`
  does not wait for that: the vehicles boot at once (EMU_BOOT_SCALE=0).
* `gcs fly` needs EXTENDED_SYS_STATE but does not request it; ArduPilot sends it only when asked
  or preloaded: the copters get the team's message-intervals file (HEARTBEAT and
  EXTENDED_SYS_STATE at 5 Hz), as its SITL flights did.

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
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink

from gcs.link import VehicleLinkConfig, VehicleProxy
from gcs.link.proxy import ParamTimeoutError
from vehicle_emulator.testing import EmulatorProcess, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

ROOT = Path(__file__).resolve().parents[2]
GUIDED, LAND, BRAKE, GUIDED_NOGPS, STABILIZE = 4, 9, 17, 20, 0
FIX = "set GUID_OPTIONS bit 3 (8): otherwise ArduPilot reads thrust as a climb rate"
COMMAND_LINE = re.compile(r"command (\d+) \(([^)]*)\) -> (\w+)")
# the team's SITL flights: HEARTBEAT and EXTENDED_SYS_STATE at 5 Hz from boot; `gcs fly` reads the
# landed state without asking for EXTENDED_SYS_STATE, which ArduPilot does not send unasked
INTERVALS_FILE = "0 200\n245 200\n"


@contextlib.contextmanager
def copters(tmp: Path, *guid_options: int, bind: bool = True,
            gcs_ports: list[int] | None = None) -> Iterator[list[EmulatorProcess]]:
    """One `vehicle-emu --id N --autopilot ardupilot` per GUID_OPTIONS value, booted at once,
    with the team's message-intervals file, on a forced bind port (``bind``) or ArduPilot's
    ephemeral one, sending to ``gcs_ports`` (default: free ports); stats JSON at exit."""
    intervals = tmp / "message-intervals-chan0.txt"
    intervals.write_text(INTERVALS_FILE)
    with contextlib.ExitStack() as stack:
        emus = [stack.enter_context(run_emulator(
            ["--id", str(k + 1), "--autopilot", "ardupilot", "--param", "EMU_BOOT_SCALE=0",
             "--param", f"GUID_OPTIONS={g}", "--message-intervals", str(intervals),
             "--stats-json", str(tmp / f"emu{k + 1}.json")],
            remote_port=gcs_ports[k] if gcs_ports else free_udp_port(), log_dir=str(tmp),
            bind=bind))
            for k, g in enumerate(guid_options)]
        yield emus


def team_file(tmp: Path, ports: list[int], gcs_ports: list[int] | None = None) -> Path:
    """square4's vehicles 1 and 2 on one edge, rates mode, linked to the copters' ports (the
    GCS listening on ``gcs_ports``, default any free port)."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "ardupilot2"
    data["vehicles"] = data["vehicles"][:2]
    data["graph"]["edges"] = [[1, 2]]
    data["controller"]["mode"] = "rates"
    for k, (v, port) in enumerate(zip(data["vehicles"], ports, strict=True)):
        v["link"] = {"local_port": gcs_ports[k] if gcs_ports else 0, "remote_host": "127.0.0.1",
                     "remote_port": port}
    path = tmp / "team.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def fly(tmp: Path, ports: list[int], *args: str, gcs_ports: list[int] | None = None
        ) -> tuple[int, str, str]:
    """`gcs fly` on the copters to its exit: (exit status, stdout, stderr)."""
    team = team_file(tmp, ports, gcs_ports)
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


def test_guid_options_without_bit_3_refuses_to_fly_and_never_arms(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground, vehicle 2 with GUID_OPTIONS at its default 0
    with copters(tmp_path, 8, 0) as emus:
        code, _, err = fly(tmp_path, [e.bind_port for e in emus])
    # THEN gcs fly refuses with one line naming vehicle 2 and the fix, and exits non-zero
    assert code == 1, err[-3000:]
    line = f"vehicle 2 (sysid 2): GUID_OPTIONS = 0 (bit mask 8 clear); {FIX}"
    assert f"gcs fly: ABORTED: {line} (exit 1)" in err.splitlines()
    # AND it read both values from the vehicles (ArduPilot casts integers to float)
    assert "vehicle 1: read_params ok: GUID_OPTIONS = 8" in err
    assert "vehicle 2: read_params ok: GUID_OPTIONS = 0" in err
    # AND neither was armed, changed mode or got a setpoint
    for k, emu in enumerate(emus, start=1):
        assert sequence(emu) == [], sequence(emu)
        s = stats(tmp_path, k)
        assert (s["mode"], s["armed"], s["setpoints_by_mode"]) == ("STABILIZE", False, {})


def test_ardupilot_takes_off_flies_guided_nogps_and_lands(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground with GUID_OPTIONS bit 3 set (72 = 64 + 8)
    with copters(tmp_path, 8, 72) as emus:
        code, out, err = fly(tmp_path, [e.bind_port for e in emus], "--duration-s", "2")
    # THEN the flight completes and lands
    assert code == 0, err[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in out
    for k, emu in enumerate(emus, start=1):
        # GUIDED, arm, NAV_TAKEOFF 2.5 m above home, BRAKE, GUIDED_NOGPS, LAND (mode 9), each
        # accepted once (ArduPilot's one COMMAND_ACK)
        assert sequence(emu) == [("mode", 4.0), ("arm", 0.0), ("takeoff", 2.5), ("mode", 17.0),
                                 ("mode", 20.0), ("mode", 9.0)], sequence(emu)
        results = {r for c, _, r in COMMAND_LINE.findall(emu.log_text()) if c in ("176", "400", "22")}
        assert results == {"ACCEPTED"}  # (gcs fly's optional ODOMETRY request is DENIED)
        s = stats(tmp_path, k)
        # LAND landed and disarmed it, and it stays in LAND (ArduPilot)
        assert (s["mode"], s["armed"]) == ("LAND", False)
        # every setpoint is one ArduPilot accepts (THROTTLE_IGNORE, a non-unit quaternion or
        # partial body rates would be rejected); priming met BRAKE (ignored there), none met
        # GUIDED; the law flew GUIDED_NOGPS, never long enough without one for GUID_TIMEOUT
        by_mode = s["setpoints_by_mode"]
        assert s["setpoints_rejected"] == 0
        assert by_mode.get("GUIDED", 0) == 0 and by_mode["BRAKE"] > 50
        assert by_mode["GUIDED_NOGPS"] > 100 and s["guided_timeouts"] == 0
        assert "Disarming motors" in emu.log_text()


def test_ardupilot_on_its_ephemeral_port_stops_gcs_fly_safely_in_preflight(tmp_path: Path) -> None:
    """Today's gap (learning the vehicle's address is the next issue's job): the copters are
    heard, but the commands go to the team file's remote_port, where nobody listens; gcs fly
    stops in preflight with the unanswered command named, and no vehicle got any command."""
    # GIVEN copters as SITL runs them: sending to the GCS's port from an ephemeral one; the
    # team file names a remote_port (it must), where no vehicle listens
    gcs_ports = [free_udp_port(), free_udp_port()]
    with copters(tmp_path, 8, 8, bind=False, gcs_ports=gcs_ports) as emus:
        code, _, err = fly(tmp_path, [free_udp_port(), free_udp_port()], "--duration-s", "1",
                           "--connect-timeout-s", "10", gcs_ports=gcs_ports)
    assert "heard vehicle 1 (sysid 1)" in err and "heard vehicle 2 (sysid 2)" in err
    assert code == 1, err[-2000:]
    assert ("configure failed: vehicle 1 (sysid 1): MAV_CMD_SET_MESSAGE_INTERVAL (511) got no "
            "COMMAND_ACK in 3 attempts") in err
    assert all(sequence(e) == [] for e in emus)


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
                assert await proxy.param_read("GUID_OPTIONS", timeout_s=0.2, retries=2) == 8.0
                # AND a parameter nobody answers raises a TimeoutError naming both
                with pytest.raises(ParamTimeoutError, match=(
                        r"^vehicle 1 \(sysid 1\): PARAM_REQUEST_READ FS_GCS_ENABLE got no "
                        r"PARAM_VALUE in 2 attempts of 0\.05 s$")):
                    await proxy.param_read("FS_GCS_ENABLE", timeout_s=0.05, retries=1)
                with pytest.raises(ValueError, match="1-16 ASCII characters"):
                    await proxy.param_read("A_NAME_LONGER_THAN_16")
        finally:
            assert peer.transport is not None
            peer.transport.close()
        return peer

    peer = asyncio.run(scenario())
    assert peer.requests == ["GUID_OPTIONS", "GUID_OPTIONS", "FS_GCS_ENABLE", "FS_GCS_ENABLE"]
    assert issubclass(ParamTimeoutError, TimeoutError)
