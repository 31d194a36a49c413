"""`gcs fly` judged by what PX4 vehicles report (issue 9, point 1 and the takeoff of point 4):
the real `gcs` CLI against real `vehicle-emu` processes of the px4 personality over 127.0.0.1
UDP, each failure of the issue reproduced on the personality, its message pinned; the ArduPilot
side is test_fly_confirmed_ardupilot.py (split from this file so that `pytest -n 2 --dist
loadfile` can run the two on different workers).

Set-up as in test_fly_emulator.py (the px4 fleet on the team file's ports, `origin: shared`),
the vehicles booting on the ground under their start positions or in the air there.
Flights are short (a 3 s formation, or a longer one that what is tested ends early): what is
tested is the sequence, not the figures.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from pymavlink import mavutil
from test_fly_emulator import Gcs, emulators

from tests.harness import MavClient, free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]

ROOT = Path(__file__).resolve().parents[2]
OFFBOARD, HOLD = 6 << 16, (4 << 16) | (3 << 24)

#: What these flights' team files say of the test machine's links (the head of each file says
#: why): the delay the cascade criterion is judged at, and rates gains that pass it.
LOADED_MACHINE_FLY = {"link_delay_s": 0.03, "rates": {"k_eps": 1.0}}
LOADED_MACHINE_NOTE = """\
# fly.link_delay_s 0.03 and fly.rates.k_eps 1 (configs/square4.yaml: the default 0.01 and 1.5):
# the links of a test machine under load. Its vehicle stand-ins, beside two other test flights on
# 2 cores, answered TIMESYNC with a lower quartile of 38 ms (19 ms each way); square4's rates
# gains pass on PX4 up to 25 ms each way, and a busier machine measures more. This file states
# 30 ms each way (judged from 35 ms) and gains the criterion passes there (modulus margin PX4
# 0.42, ArduPilot 0.47); what is tested is the sequence, not the figures.
"""


def write_team(path: Path, data: dict) -> Path:
    """The team file, with `LOADED_MACHINE_FLY` in its fly section and the note at its head."""
    data["fly"].update(link_delay_s=LOADED_MACHINE_FLY["link_delay_s"])
    data["fly"].setdefault("rates", {}).update(LOADED_MACHINE_FLY["rates"])
    path.write_text(LOADED_MACHINE_NOTE + yaml.safe_dump(data, sort_keys=False))
    return path


def px4_team(tmp: Path, *, duration_s: float, ground: bool = True, name: str = "team",
             origins: dict[int, list[float]] | None = None, fly: dict | None = None,
             faults: list | None = None, params: dict[int, dict] | None = None,
             z_shift: float = 0.0) -> Path:
    """configs/square4.yaml on free ports, rates mode, the px4 personality, vehicles booting on
    the ground under their team-file start positions (``ground``; the go-to-start phase then
    climbs them there) or in the air there; the start positions ``z_shift`` m higher; the links
    of a loaded test machine (`write_team`)."""
    gcs_base, bind_base = free_udp_port_block(4), free_udp_port_block(4)
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = name
    data["mission"]["duration_s"] = duration_s
    data["controller"]["mode"] = "rates"
    data["fly"]["geofence"]["min_enu_m"][2] = 0.5
    data["fly"].update(fly or {})
    data["faults"] = faults or []
    data["emulator"] = {"autopilot": "px4", "origin": "shared"}
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_port": bind_base + k}
        v["initial"]["position_enu_m"][2] += z_shift
        v["emulator"] = {}
        if ground:
            x, y, _ = v["initial"]["position_enu_m"]
            v["emulator"]["boot_position_enu_m"] = [x, y, 0.0]
        if origins and v["id"] in origins:
            v["emulator"]["origin_enu_m"] = origins[v["id"]]
    return write_team(tmp / f"{name}.yaml", data)


def fly_once(team: Path, out: Path, *args: str, timeout_s: float = 200) -> tuple[int, str, str]:
    gcs = Gcs(team, out, "--mode", "rates", *args)
    code, stdout = gcs.finish(timeout_s)
    return code, stdout, gcs.log_path.read_text()


def commands_sent(tlog: Path, sysid: int) -> list[tuple[int, float, float]]:
    """(command, param2, param3) of every COMMAND_LONG the GCS sent to `sysid`, in order."""
    conn = mavutil.mavlink_connection(str(tlog))
    out = []
    while (msg := conn.recv_match(type="COMMAND_LONG")) is not None:
        row = (msg.command, msg.param2, msg.param3)
        if msg.target_system == sysid and msg.command in (176, 400, 22, 21) and (
                not out or out[-1] != row):
            out.append(row)
    return out


def test_px4_left_in_offboard_by_a_failsafe_landing_is_armed_in_hold(tmp_path: Path) -> None:
    # GIVEN a flight whose ground station dies in the formation: PX4's offboard-loss failsafe
    # (Position, no RC: descend) lands every vehicle, "Disarmed by landing", and PX4 v1.16.0
    # returns to OFFBOARD, disarmed, where it refuses to arm (issue 9's second flight). The
    # starts 5 m lower (3-7 m up): a shorter climb, failsafe descent and landing
    team = px4_team(tmp_path, duration_s=60.0, z_shift=-5.0)
    with emulators(team, 0, tmp_path):
        gcs = Gcs(team, tmp_path / "killed", "--mode", "rates")
        gcs.wait_for("mission: phase formation", 120)
        gcs.wait_for("vehicle 4: offboard ok", 10)
        gcs.proc.kill()
        gcs.proc.wait(10)
        ports = [v["link"]["local_port"] for v in yaml.safe_load(team.read_text())["vehicles"]]
        for k, port in enumerate(ports, start=1):
            client = MavClient(port, target_system=k)
            try:
                client.wait("HEARTBEAT", 60.0, lambda m: m.custom_mode == OFFBOARD
                            and not m.base_mode & 128 and m.system_status == 0)
            finally:
                client.close()
        # WHEN gcs fly is run again (a 3 s formation: the team file's 60 s only keeps the first
        # flight in its formation until it is killed; what is tested here is the arming)
        code, out, log = fly_once(team, tmp_path / "again", "--duration-s", "3")
        # THEN each vehicle is put in Hold (confirmed) before arming, and the flight completes
        assert code == 0, log[-3000:]
        for k in range(1, 5):
            assert f"vehicle {k}: arm_mode ok" in log
            sent = commands_sent(tmp_path / "again" / "flight.tlog", k)
            assert sent[:2] == [(176, 4.0, 3.0), (400, 0.0, 0.0)], sent
        # AND no arming attempt was refused: it was not tried in OFFBOARD
        assert "Arming denied" not in log


def test_px4_takeoff_is_judged_by_height_above_home_not_the_ekf_origin_z(tmp_path: Path) -> None:
    # GIVEN vehicles 2 and 3 whose EKF origin is 2 m above the ground they take off from: at
    # 2.5 m above home their LOCAL_POSITION_NED reads 0.5 m up (issue 9: "vehicles [2, 3] did not
    # reach 2.5 m within 60 s", the check compared the EKF-origin z with the home-relative
    # altitude; the team frame of gcs/fly/origins.py now places such a frame right, and the
    # takeoff is judged without either: by the vehicle's own height above home)
    # (the starts 5 m lower, 3-7 m up: a shorter climb and landing, the same takeoff)
    origins = {2: [3.0, -4.0, 2.0], 3: [-5.0, -4.0, 2.0]}
    team = px4_team(tmp_path, duration_s=3.0, origins=origins, z_shift=-5.0,
                    fly={"takeoff_timeout_s": 20.0,
                         "geofence": {"min_enu_m": [-60.0, -60.0, -5.0],
                                      "max_enu_m": [60.0, 60.0, 60.0]}})
    # booted once gcs fly waits for them (PX4 v1.16.0 refuses arming for ~3 s after boot;
    # started the other way round, a slow ground-station start-up may come after the 3 s)
    gcs = Gcs(team, tmp_path / "run", "--mode", "rates")
    gcs.wait_for("INFO gcs.fly: rates mode with", 120)
    with emulators(team, 0, tmp_path):
        code, _ = gcs.finish(200)
    log = gcs.log_path.read_text()
    # THEN every takeoff is complete from the vehicles' own height above home: exit 0
    assert code == 0, log[-3000:]
    assert "mission: phase prime" in log and "did not complete the takeoff" not in log
    # AND the flight waited for every vehicle's pre-arm checks, and every mode change and the
    # arming were confirmed (no ACK left unread)
    for k in range(1, 5):
        assert f"vehicle {k} (sysid {k}): waiting for its pre-arm checks (SYS_STATUS)" in log
        assert f"vehicle {k}: arm ok" in log and f"vehicle {k}: offboard ok" in log


def test_px4_refusing_offboard_after_an_accepted_ack_ends_with_exit_1(tmp_path: Path) -> None:
    # GIVEN vehicle 3 with COM_OF_LOSS_T = 0: PX4 v1.16.0 then answers OFFBOARD with ACCEPTED
    # (its MAVLink receiver) and TEMPORARILY_REJECTED (its commander), as it did to actuator
    # setpoints; the first ACK alone made issue 9's flight "complete"
    team = px4_team(tmp_path, duration_s=20.0, ground=False)
    port = yaml.safe_load(team.read_text())["vehicles"][2]["link"]["local_port"]
    with emulators(team, 0, tmp_path):
        client = MavClient(port, target_system=3)
        try:
            client.wait("HEARTBEAT", 60.0)
            assert client.set_param("COM_OF_LOSS_T", 0.0).param_value == 0.0
        finally:
            client.close()
        code, out, log = fly_once(team, tmp_path / "run")
    # THEN the refusal wins, the flight stops with exit 1 and the line names what was seen
    assert code == 1, log[-3000:]
    assert ("vehicle 3 (sysid 3): MAV_CMD_DO_SET_MODE (176) for mode OFFBOARD refused: "
            "HEARTBEAT reports AUTO_LOITER, armed; COMMAND_ACKs seen: ACCEPTED, "
            "TEMPORARILY_REJECTED; the vehicle said CRITICAL \"Switching to Offboard is "
            "currently not available\"") in out + log
    assert "formation complete" not in out


def test_px4_vehicle_that_cannot_follow_stops_the_flight_by_the_formation_rule(
        tmp_path: Path) -> None:
    # GIVEN UAV 2 (1.2 kg) with its rotors at 30 % from the formation start: 9.6 N of thrust
    # for 11.8 N of weight, it sinks to the ground while its mode, link and attitude look fine
    weak = [{"kind": "motor_efficiency", "vehicle": 2, "at_s": 0.0, "motor": m,
             "efficiency": 0.3} for m in (1, 2, 3, 4)]
    team = px4_team(tmp_path, duration_s=40.0, ground=False, faults=weak,
                    fly={"geofence": {"min_enu_m": [-60.0, -60.0, -5.0],
                                      "max_enu_m": [60.0, 60.0, 60.0]},
                         # judged at 5 s: UAV 2 is then on the ground and the error ~10 m
                         # against a bound of ~3.3 m (0.5 x 6.6 m); by 10 s its neighbours,
                         # pulled down to it by the law's coupling, have closed it to 3.3-4.6 m
                         "formation_check": {"after_s": 5.0}})
    with emulators(team, 0, tmp_path):
        code, out, log = fly_once(team, tmp_path / "run")
    # THEN the flight stops at t = 5 s by the rule of docs/gcs.md, exit 1
    assert code == 1, log[-3000:]
    match = re.search(r"the vehicles do not follow the formation: error ([\d.]+) m at t = "
                      r"5\.0 s > ([\d.]+) m = max\(1 m, 0\.5 x ([\d.]+) m at t = 0\) "
                      r"\(fly\.formation_check\)", out + log)
    assert match is not None, log[-3000:]
    assert float(match[1]) > float(match[2]) >= 1.0
