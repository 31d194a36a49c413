"""A mixed team (issue 9's acceptance): Scenario I with two PX4 and two ArduPilot vehicles of the
emulator's personalities in one `vehicle-emu --fleet`, each on its own link as the real ones
are (PX4 SITL's fixed ports, ArduPilot's ephemeral source port learned), flown from the ground
twice without restarting the vehicles by the real `gcs` CLI over 127.0.0.1 UDP."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from test_fly_confirmed import commands_sent, fly_once, write_team

from vehicle_emulator.testing import free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(500)]

ROOT = Path(__file__).resolve().parents[2]
AUTOPILOTS = {1: "px4", 2: "ardupilot", 3: "px4", 4: "ardupilot"}


def mixed_team(tmp: Path, duration_s: float, z_shift: float = 0.0) -> Path:
    gcs_base, bind_base = free_udp_port_block(4), free_udp_port_block(4)
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "mixed4"
    data["mission"]["duration_s"] = duration_s
    data["fly"]["geofence"]["min_enu_m"][2] = 0.5
    data["faults"] = []
    data["emulator"] = {"origin": "shared"}
    for k, v in enumerate(data["vehicles"]):
        autopilot = AUTOPILOTS[v["id"]]
        v["initial"]["position_enu_m"][2] += z_shift
        x, y, _ = v["initial"]["position_enu_m"]
        v["emulator"] = {"autopilot": autopilot, "boot_position_enu_m": [x, y, 0.0]}
        v["link"] = ({"local_port": gcs_base + k, "remote_port": bind_base + k}
                     if autopilot == "px4" else {"local_port": gcs_base + k, "learn_remote": True})
    return write_team(tmp / "mixed4.yaml", data)


def test_mixed_px4_and_ardupilot_team_flies_from_the_ground_twice(tmp_path: Path) -> None:
    # GIVEN Scenario I with vehicles 1 and 3 on PX4, 2 and 4 on ArduPilot (GUID_OPTIONS 8, its
    # boot on a quarter of the recorded timeline), all on the ground below their starts, which
    # are 5 m lower than Scenario I's (3-7 m up: a shorter climb and landing, the same sequence)
    team = mixed_team(tmp_path, duration_s=3.0, z_shift=-5.0)
    fleet = subprocess.Popen(
        [sys.executable, "-m", "vehicle_emulator.cli", "--fleet", "--team", str(team),
         "--param", "GUID_OPTIONS=8", "--param", "EMU_BOOT_SCALE=0.25", "--log-level", "WARNING"],
        stdout=subprocess.DEVNULL, stderr=open(tmp_path / "fleet.log", "w"))  # noqa: SIM115
    try:
        for run in ("first", "second"):
            # WHEN gcs fly flies it (the second time: the same vehicles, landed and disarmed)
            code, out, log = fly_once(team, tmp_path / run, timeout_s=300)
            # THEN each flight goes to the start, flies, lands, disarms: exit 0
            assert code == 0, log[-3000:]
            assert "gcs fly: done: formation complete (exit 0)" in out
            for k, autopilot in AUTOPILOTS.items():
                assert f"vehicle {k}: offboard ok" in log, log[-3000:]
                sent = commands_sent(tmp_path / run / "flight.tlog", k)
                modes = [(c, p2) for c, p2, _ in sent if c == 176]
                # each in its own autopilot's modes: PX4 OFFBOARD (main 6), ArduPilot
                # GUIDED_NOGPS (20)
                offboard = (176, 1.0 * (6 if autopilot == "px4" else 20))
                assert offboard in [(c, p2) for c, p2 in modes], (k, sent)
    finally:
        fleet.terminate()
        fleet.wait(timeout=20)
