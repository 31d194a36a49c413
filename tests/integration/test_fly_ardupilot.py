"""`gcs fly` against fake ArduPilot Copters: the real `gcs` CLI as a subprocess, and small
ArduCopter-like peers written with plain pymavlink on 127.0.0.1 UDP in the test's event loop.

The fake (`FakeArduCopter`) holds still: HEARTBEAT autopilot 3, type quadrotor, custom_mode = its
mode number; COMMAND_LONG answered with COMMAND_ACK (DO_SET_MODE and SET_MODE applied, arming,
NAV_TAKEOFF in GUIDED to a relative altitude, the LAND mode lands and disarms), PARAM_REQUEST_READ
answered for GUID_OPTIONS, SET_MESSAGE_INTERVAL honoured for the streams preflight needs
(ATTITUDE_QUATERNION, LOCAL_POSITION_NED, HIGHRES_IMU at the tick rate; EXTENDED_SYS_STATE).
SET_ATTITUDE_TARGET is checked the way ArduPilot Copter does (THROTTLE_IGNORE rejected, a unit
quaternion, all three body rates or none) and recorded with the mode it arrived in. Tests wait on
the CLI's exit, with timeouts; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink

from gcs.link import VehicleLinkConfig, VehicleProxy
from gcs.link.proxy import ParamTimeoutError

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]
Msg = mavlink.MAVLink_message
GUIDED, LAND, BRAKE, GUIDED_NOGPS, STABILIZE = 4, 9, 17, 20, 0
STREAM_IDS = {31: "ATTITUDE_QUATERNION", 32: "LOCAL_POSITION_NED", 105: "HIGHRES_IMU",
              245: "EXTENDED_SYS_STATE", 0: "HEARTBEAT", 33: "GLOBAL_POSITION_INT"}
FIX = "set GUID_OPTIONS bit 3 (8): otherwise ArduPilot reads thrust as a climb rate"


@dataclass
class Setpoint:
    t_s: float
    mode: int
    msg: Msg
    rejected: str = ""  # why ArduPilot would drop it ('' accepted)


@dataclass
class FakeArduCopter(asyncio.DatagramProtocol):
    """An ArduCopter-like vehicle that holds still (see the module docstring)."""

    sysid: int
    guid_options: float
    position_enu_m: tuple[float, float]
    mode: int = STABILIZE
    armed: bool = False
    altitude_m: float = 0.0
    landed: bool = True
    commands: list[Msg] = field(default_factory=list)
    modes: list[tuple[float, int]] = field(default_factory=list)  # (time, mode) after changes
    setpoints: list[Setpoint] = field(default_factory=list)
    param_requests: list[str] = field(default_factory=list)
    drop_param_requests: int = 0  # leave the first N PARAM_REQUEST_READs unanswered
    interval_s: dict[str, float] = field(default_factory=lambda: {
        "HEARTBEAT": 1.0, "ATTITUDE_QUATERNION": 0.1, "LOCAL_POSITION_NED": 0.1,
        "HIGHRES_IMU": 0.1, "EXTENDED_SYS_STATE": 0.2, "GLOBAL_POSITION_INT": 0.2})

    def __post_init__(self) -> None:
        self.mav = mavlink.MAVLink(None, self.sysid, 1)
        self.transport: asyncio.DatagramTransport | None = None
        self.gcs: tuple[str, int] | None = None
        self.heard = asyncio.Event()
        self.events: list[tuple[float, str]] = []  # timed state changes (takeoff, landing)
        self.loop = asyncio.get_running_loop()
        self.modes.append((self.loop.time(), self.mode))

    # --- socket ----------------------------------------------------------------------------------

    async def start(self) -> int:
        self.transport, _ = await self.loop.create_datagram_endpoint(
            lambda: self, local_addr=("127.0.0.1", 0))
        self._task = asyncio.create_task(self._stream())
        return int(self.transport.get_extra_info("sockname")[1])

    async def stop(self) -> None:
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        assert self.transport is not None
        self.transport.close()

    def send(self, msg: Msg) -> None:
        assert self.transport is not None and self.gcs is not None
        self.transport.sendto(msg.pack(self.mav), self.gcs)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:  # type: ignore[override]
        self.gcs = self.gcs or addr
        self.heard.set()
        for msg in self.mav.parse_buffer(data) or []:
            kind = msg.get_type()
            if kind == "COMMAND_LONG":
                self.commands.append(msg)
                self.send(self.mav.command_ack_encode(msg.command, self._command(msg), 0, 0,
                                                      msg.get_srcSystem(), msg.get_srcComponent()))
            elif kind == "SET_MODE":
                self._set_mode(int(msg.custom_mode))
            elif kind == "PARAM_REQUEST_READ":
                self.param_requests.append(msg.param_id)
                if len(self.param_requests) <= self.drop_param_requests:
                    continue
                if msg.param_id == "GUID_OPTIONS":
                    self.send(self.mav.param_value_encode(b"GUID_OPTIONS", self.guid_options,
                                                          6, 1, 0))  # MAV_PARAM_TYPE_INT32
            elif kind == "SET_ATTITUDE_TARGET":
                self.setpoints.append(Setpoint(self.loop.time(), self.mode, msg,
                                               self._check_setpoint(msg)))

    # --- behaviour -------------------------------------------------------------------------------

    def _set_mode(self, mode: int) -> int:
        if mode not in (STABILIZE, GUIDED, 5, LAND, BRAKE, GUIDED_NOGPS):
            return mavlink.MAV_RESULT_UNSUPPORTED
        if mode != self.mode:
            self.mode = mode
            self.modes.append((self.loop.time(), mode))
            if mode == LAND and not self.landed:
                self.events.append((self.loop.time() + 0.3, "landed"))
        return mavlink.MAV_RESULT_ACCEPTED

    def _command(self, c: Msg) -> int:
        if c.command == mavlink.MAV_CMD_DO_SET_MODE:
            return self._set_mode(int(c.param2)) if int(c.param1) & 1 else mavlink.MAV_RESULT_DENIED
        if c.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if c.param1 == 1.0:
                if not self.landed or self.mode not in (STABILIZE, GUIDED):
                    return mavlink.MAV_RESULT_FAILED
                self.armed = True
            else:
                self.armed = False
            return mavlink.MAV_RESULT_ACCEPTED
        if c.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not (self.armed and self.mode == GUIDED and self.landed):
                return mavlink.MAV_RESULT_FAILED
            self.landed = False
            self.events.append((self.loop.time() + 0.3, f"at {c.param7}"))
            return mavlink.MAV_RESULT_ACCEPTED
        if c.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            kind = STREAM_IDS.get(int(c.param1))
            if kind is not None:
                self.interval_s[kind] = math.inf if c.param2 < 0 else c.param2 * 1e-6
            return mavlink.MAV_RESULT_ACCEPTED
        return mavlink.MAV_RESULT_UNSUPPORTED  # NAV_LAND included: the LAND mode is expected

    @staticmethod
    def _check_setpoint(m: Msg) -> str:
        if m.type_mask & 64:
            return "THROTTLE_IGNORE"
        if abs(math.sqrt(sum(x * x for x in m.q)) - 1.0) > 1e-3:
            return "quaternion not unit length"
        rates_ignored = [bool(m.type_mask & b) for b in (1, 2, 4)]
        if any(rates_ignored) and not all(rates_ignored):
            return "some body rates ignored"
        return ""

    def _advance(self, now: float) -> None:
        for event in [e for e in self.events if e[0] <= now]:
            self.events.remove(event)
            if event[1] == "landed":
                self.altitude_m, self.landed, self.armed = 0.0, True, False  # LAND disarms
            else:
                self.altitude_m = float(event[1].split()[1])

    async def _stream(self) -> None:
        """Every stream at its interval (inf: off), on absolute due times; wakes at least every
        10 ms so that a changed interval takes effect."""
        await self.heard.wait()
        due: dict[str, float] = {}
        while True:
            now = self.loop.time()
            self._advance(now)
            for kind, interval in self.interval_s.items():
                if math.isfinite(interval) and due.setdefault(kind, now) <= now:
                    self.send(self._message(kind))
                    due[kind] = max(due[kind] + interval, now)
            wake = min([now + 0.01] + [due[k] for k, i in self.interval_s.items()
                                       if math.isfinite(i) and k in due])
            await asyncio.sleep(max(0.0, wake - self.loop.time()))  # pacing, not synchronising

    def _message(self, kind: str) -> Msg:
        ms = int(self.loop.time() * 1000) & 0xFFFFFFFF
        x_e, y_n = self.position_enu_m
        if kind == "HEARTBEAT":
            return self.mav.heartbeat_encode(2, 3, 1 | (128 if self.armed else 0), self.mode,
                                             4 if self.armed else 3)
        if kind == "ATTITUDE_QUATERNION":
            return self.mav.attitude_quaternion_encode(ms, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if kind == "LOCAL_POSITION_NED":
            return self.mav.local_position_ned_encode(ms, y_n, x_e, -self.altitude_m, 0, 0, 0)
        if kind == "HIGHRES_IMU":
            return self.mav.highres_imu_encode(ms * 1000, 0.0, 0.0, -9.81, 0, 0, 0, 0, 0, 0,
                                               0, 0, 0, 0, 0x3F)
        if kind == "EXTENDED_SYS_STATE":
            state = (1 if self.landed else 3 if self.altitude_m == 0.0
                     else 4 if self.mode == LAND else 2)
            return self.mav.extended_sys_state_encode(0, state)
        return self.mav.global_position_int_encode(ms, 0, 0, int(self.altitude_m * 1000),
                                                   int(self.altitude_m * 1000), 0, 0, 0, 0)

    # --- what it saw -----------------------------------------------------------------------------

    def sequence(self) -> list[tuple[str, float]]:
        """Mode changes, arming and take-off commands in the order received."""
        out = []
        for c in self.commands:
            if c.command == mavlink.MAV_CMD_DO_SET_MODE:
                out.append(("mode", c.param2))
            elif c.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
                out.append(("arm" if c.param1 == 1.0 else "disarm", c.param2))
            elif c.command in (mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND):
                out.append(("takeoff" if c.command == 22 else "nav_land", c.param7))
        return out


def team_file(tmp: Path, ports: list[int]) -> Path:
    """square4's vehicles 1 and 2 on one edge, rates mode, linked to the fakes' ports."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "ardupilot2"
    data["vehicles"] = data["vehicles"][:2]
    data["graph"]["edges"] = [[1, 2]]
    data["controller"]["mode"] = "rates"
    for v, port in zip(data["vehicles"], ports, strict=True):
        v["link"] = {"local_port": 0, "remote_host": "127.0.0.1", "remote_port": port}
    path = tmp / "team.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


async def fly(tmp: Path, fakes: list[FakeArduCopter], *args: str) -> tuple[int, str, str]:
    """Start the fakes, run `gcs fly` on them to its exit; (exit status, stdout, stderr)."""
    ports = [await f.start() for f in fakes]
    try:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "gcs.cli", "fly", "--team", str(team_file(tmp, ports)),
            "--out", str(tmp / "run"), "--no-figures", "--status", "off", "--log-level", "INFO",
            "--mode", "rates", *args, stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        try:
            out, err = await asyncio.wait_for(proc.communicate(), 90)
        except TimeoutError:
            proc.kill()
            raise
        return int(proc.returncode or 0), out.decode(), err.decode()
    finally:
        for f in fakes:
            await f.stop()


def on_ground(sysid: int, guid_options: float) -> FakeArduCopter:
    return FakeArduCopter(sysid, guid_options, (4.0 * sysid, -3.0))


def test_guid_options_without_bit_3_refuses_to_fly_and_never_arms(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground, vehicle 2 with GUID_OPTIONS = 0
    async def scenario() -> tuple[list[FakeArduCopter], tuple[int, str, str]]:
        fakes = [on_ground(1, 8.0), on_ground(2, 0.0)]
        return fakes, await fly(tmp_path, fakes)

    fakes, (code, _, err) = asyncio.run(scenario())
    # THEN gcs fly refuses with one line naming vehicle 2 and the fix, and exits non-zero
    assert code == 1, err[-3000:]
    line = f"vehicle 2 (sysid 2): GUID_OPTIONS = 0 (bit mask 8 clear); {FIX}"
    assert f"gcs fly: ABORTED: {line} (exit 1)" in err.splitlines()
    # AND both were asked for GUID_OPTIONS, neither was armed nor sent a setpoint
    for f in fakes:
        assert f.param_requests == ["GUID_OPTIONS"]
        assert not any(c.command == 400 and c.param1 == 1.0 for c in f.commands)
        assert f.setpoints == [] and not f.armed and f.mode == STABILIZE


def test_ardupilot_takes_off_flies_guided_nogps_and_lands(tmp_path: Path) -> None:
    # GIVEN two ArduPilot Copters on the ground with GUID_OPTIONS = 8
    async def scenario() -> tuple[list[FakeArduCopter], tuple[int, str, str]]:
        fakes = [on_ground(1, 8.0), on_ground(2, 72.0)]
        return fakes, await fly(tmp_path, fakes, "--duration-s", "2")

    fakes, (code, out, err) = asyncio.run(scenario())
    # THEN the flight completes and lands
    assert code == 0, err[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in out
    for f in fakes:
        # GUIDED, arm, NAV_TAKEOFF 2.5 m above home, BRAKE, GUIDED_NOGPS, LAND (mode 9)
        assert f.sequence() == [("mode", 4.0), ("arm", 0.0), ("takeoff", 2.5), ("mode", 17.0),
                                ("mode", 20.0), ("mode", 9.0)], f.sequence()
        assert (f.mode, f.armed, f.landed) == (LAND, False, True)
        # every setpoint is one ArduPilot accepts: rates + thrust, unit q, thrust in 0..1
        assert f.setpoints and all(s.rejected == "" for s in f.setpoints)
        for s in f.setpoints:
            m = s.msg
            assert m.type_mask == 128 and (m.target_system, m.target_component) == (f.sysid, 1)
            assert abs(math.sqrt(sum(x * x for x in m.q)) - 1.0) < 1e-6
            assert 0.0 <= m.thrust <= 1.0
        # priming arrived in BRAKE (ignored there), none in GUIDED; the law flew GUIDED_NOGPS
        by_mode = {mode: sum(s.mode == mode for s in f.setpoints) for mode in (4, 17, 20)}
        assert by_mode[GUIDED] == 0 and by_mode[BRAKE] > 50 and by_mode[GUIDED_NOGPS] > 100
        # AND never in GUIDED_NOGPS without setpoints: no gap over 0.5 s from entry to exit
        # (GUID_TIMEOUT is 3 s)
        enter = next(t for t, mode in f.modes if mode == GUIDED_NOGPS)
        leave = next(t for t, mode in f.modes if t > enter and mode != GUIDED_NOGPS)
        times = [enter] + [s.t_s for s in f.setpoints if enter <= s.t_s <= leave] + [leave]
        assert max(b - a for a, b in zip(times, times[1:], strict=False)) < 0.5


def test_param_read_answers_retries_and_times_out_naming_vehicle_and_parameter() -> None:
    async def scenario() -> FakeArduCopter:
        # GIVEN a vehicle that leaves the first PARAM_REQUEST_READ unanswered
        fake = FakeArduCopter(1, 8.0, (0.0, 0.0), drop_param_requests=1)
        port = await fake.start()
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
            await fake.stop()
        return fake

    fake = asyncio.run(scenario())
    assert fake.param_requests == ["GUID_OPTIONS", "GUID_OPTIONS", "FS_GCS_ENABLE",
                                   "FS_GCS_ENABLE"]
    assert issubclass(ParamTimeoutError, TimeoutError)
