"""`vehicle-emu --fleet --team FILE` takes what a team file written for real SITL states: the
team frame's origin on the globe (`frame.origin`), the parameters the real vehicles were booted
with (`emulator.autopilot_params`), and the command line's port bases over the file's ports.

Real `vehicle-emu` processes on 127.0.0.1, real pymavlink clients, the recorded 2026-12-04 team
files (tests/data/sitl/; ports rewritten to free ones) and the real `gcs fly`.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import clients_on_port_block, free_udp_port_block
from vehicle_emulator.physics.geodesy import geodetic_to_enu

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "sitl"
EMU = [sys.executable, "-m", "vehicle_emulator"]


def recorded_team(name: str) -> dict:
    """A recorded team file (tests/data/sitl/, copied from the 2026-12-04 flights)."""
    return yaml.safe_load((DATA / name).read_text())


def write(tmp: Path, data: dict, name: str = "team.yaml") -> Path:
    path = tmp / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_fleet_port_bases_override_the_team_files_ports(tmp_path: Path) -> None:
    # GIVEN the PX4 SIH team file, its links on a block of free ports (as PX4 SITL's layout)
    data = recorded_team("team_px4sih.yaml")
    file_gcs, file_bind = free_udp_port_block(4), free_udp_port_block(4)
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": file_gcs + k, "remote_host": "127.0.0.1",
                     "remote_port": file_bind + k}
    team = write(tmp_path, data)
    # WHEN the fleet starts with --bind-base and --remote-base elsewhere
    clients = clients_on_port_block(4)
    bind_base = free_udp_port_block(4)
    log_path = tmp_path / "fleet.log"
    proc = subprocess.Popen(
        [*EMU, "--fleet", "--team", str(team), "--bind-base", str(bind_base),
         "--remote-base", str(clients[0].port)],
        stdout=subprocess.DEVNULL, stderr=open(log_path, "w"))  # noqa: SIM115
    try:
        for k, c in enumerate(clients):
            # THEN vehicle k+1 sends to remote_base + k and answers a command there, from
            # bind_base + k (the client answers the address it heard)
            c.wait("HEARTBEAT", 90)
            assert c.peers == {("127.0.0.1", bind_base + k)}
            assert c.command_acks(512, 148, count=1) == [0]  # REQUEST_MESSAGE: ACCEPTED
        # AND nothing is bound on the team file's ports any more
        for k in range(4):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind(("127.0.0.1", file_bind + k))
    finally:
        proc.terminate()
        proc.wait(10)
        for c in clients:
            c.close()
    # AND the log says which ports were used and that the flags overrode the file
    log = log_path.read_text()
    assert (f"--bind-base {bind_base} overrides the team file's link.remote_port" in log), log
    assert f"--remote-base {clients[0].port} overrides the team file's link.local_port" in log
    assert (f"vehicle 4 sysid 4: binds 127.0.0.1:{bind_base + 3} -> "
            f"127.0.0.1:{clients[0].port + 3}") in log
    assert "Traceback" not in log


def test_home_and_origin_come_from_the_team_files_frame_origin(tmp_path: Path) -> None:
    # GIVEN the PX4 SIH team file (frame.origin: SIH's home, 47.397742, 8.545594, 489.4 m; the
    # emulator's own default is 488.0 m), vehicle 2 booted 3 m east and 4 m south of it
    data = recorded_team("team_px4sih.yaml")
    lat0, lon0, alt0 = data["frame"]["origin"]
    assert alt0 == 489.4
    data["vehicles"][1]["emulator"]["boot_position_enu_m"] = [3.0, -4.0, 0.0]
    clients = clients_on_port_block(4)
    bind_base = free_udp_port_block(4)
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": clients[0].port + k, "remote_host": "127.0.0.1",
                     "remote_port": bind_base + k}
    team = write(tmp_path, data)
    proc = subprocess.Popen([*EMU, "--fleet", "--team", str(team)], stdout=subprocess.DEVNULL,
                            stderr=open(tmp_path / "fleet.log", "w"))  # noqa: SIM115
    try:
        for k in (0, 1):
            c = clients[k]
            boot_enu = data["vehicles"][k]["emulator"]["boot_position_enu_m"]
            c.wait("HEARTBEAT", 90)
            # (the client's socket filled with the vehicle's telemetry while the one before was
            # checked: read it down first, or the answer may find the buffer full)
            c.collect(0.5)
            # WHEN a client asks for the EKF origin
            c.send(mavlink.MAVLink_command_long_message(k + 1, 1, 512, 0, 49, 0, 0, 0, 0, 0, 0))
            origin = c.wait("GPS_GLOBAL_ORIGIN", 5)
            # THEN it is the ground point below the boot position, about frame.origin: at
            # 489.4 m for vehicle 1 (was 488.0)
            enu = geodetic_to_enu(origin.latitude * 1e-7, origin.longitude * 1e-7,
                                  origin.altitude * 1e-3, lat0, lon0, alt0)
            assert enu == pytest.approx(boot_enu, abs=0.02)
            # AND HOME_POSITION and GLOBAL_POSITION_INT (on the ground) are there too
            home = c.wait("HOME_POSITION", 5)
            enu = geodetic_to_enu(home.latitude * 1e-7, home.longitude * 1e-7,
                                  home.altitude * 1e-3, lat0, lon0, alt0)
            assert enu == pytest.approx(boot_enu, abs=0.05)
            # (the estimate, which wanders as PX4's does: within 0.7 m here, half the 1.4 m
            # that the emulator's own home altitude was off)
            gp = c.wait("GLOBAL_POSITION_INT", 5)
            enu = geodetic_to_enu(gp.lat * 1e-7, gp.lon * 1e-7, gp.alt * 1e-3, lat0, lon0, alt0)
            assert enu == pytest.approx(boot_enu, abs=0.7)
        assert clients[0].seen("GPS_GLOBAL_ORIGIN")[-1].altitude == 489400
    finally:
        proc.terminate()
        proc.wait(10)
        for c in clients:
            c.close()


@pytest.mark.parametrize(("params", "message"), [
    ({"GUID_OPTION": 8}, "emulator.autopilot_params.GUID_OPTION: the ardupilot personality has "
                         "no parameter 'GUID_OPTION' (docs/emulator.md, Parameters)"),
    ({"GUID_OPTIONS": "eight"}, "emulator.autopilot_params.GUID_OPTIONS: expected a number, "
                                "got 'eight'"),
])
def test_a_bad_autopilot_parameter_is_one_line_naming_the_key(
        tmp_path: Path, params: dict, message: str) -> None:
    # GIVEN the ArduCopter SITL team file with a misspelt name or a non-number
    data = recorded_team("team_arducopter_sitl.yaml")
    data["emulator"] = {"autopilot": "ardupilot", "autopilot_params": params}
    team = write(tmp_path, data)
    # WHEN the fleet starts THEN it exits 2 with one line naming the key path
    out = subprocess.run([*EMU, "--fleet", "--team", str(team)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1] == f"vehicle-emu: {team}: {message}"


def test_the_arducopter_sitl_team_file_flies_the_emulator_unchanged(tmp_path: Path) -> None:
    # GIVEN the team file written for four real ArduCopter SITL vehicles (booted with
    # GUID_OPTIONS 8 at frame.origin, Canberra, 584 m), its ports rewritten to free ones, and
    # the one section a user adds for the emulator: the personality and the parameters the
    # real vehicles were booted with
    data = recorded_team("team_arducopter_sitl.yaml")
    gcs_base = free_udp_port_block(4)
    for k, v in enumerate(data["vehicles"]):
        v["link"]["local_port"] = gcs_base + k
    data["emulator"] = {"autopilot": "ardupilot", "autopilot_params": {"GUID_OPTIONS": 8}}
    team = write(tmp_path, data)
    # WHEN `vehicle-emu --fleet --team` runs it (booted at once, to keep the test short) and
    # `gcs fly` flies it
    emu = subprocess.Popen([*EMU, "--fleet", "--team", str(team), "--param", "EMU_BOOT_SCALE=0"],
                           stdout=subprocess.DEVNULL,
                           stderr=open(tmp_path / "fleet.log", "w"))  # noqa: SIM115
    try:
        fly = subprocess.run(
            [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out",
             str(tmp_path / "run"), "--no-figures", "--status", "off", "--duration-s", "3"],
            stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=200,
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, check=False)
    finally:
        emu.terminate()
        emu.wait(10)
    # THEN the preflight finds GUID_OPTIONS 8 and every origin at the team frame's origin (no
    # `GUID_OPTIONS = 0 (bit mask 8 clear)`, no origin 3.3e6 m away), and the flight lands
    assert "bit mask 8 clear" not in fly.stderr
    assert "from the team frame's origin" not in fly.stderr
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in fly.stdout
