"""`gcs fly --mode attitude` from the ground against the px4 and ardupilot personalities, with the
initial mass estimate from the hover and the heading held.

Reproduces the real-autopilot issue's formation-start failure: PX4 SIH vehicles took off to
2.5 m and, with the scenario's initial estimates (half the mass for some), sank 2 m at the
formation start: `geofence breach: z = 0.44 m`. With `estimates.mhat: from_hover` the law starts
at the thrust the autopilot itself hovered with, so nothing sinks; the attitude mode's command
attitude carries each vehicle's own heading (`fly.heading: hold`), so none yaws.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from pymavlink import mavutil
from test_fly_ardupilot import copters, gcs_ports
from test_fly_emulator import Gcs, emulators

from tests.harness import free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
YAWS_ENU_RAD = (0.4, -1.2, 2.0, 0.0)  # start headings, ENU yaw (0 east, counter-clockwise)


def ground_team(tmp: Path, bind_base: int, duration_s: float) -> Path:
    """Scenario I on the px4 personality: every vehicle on the ground below its start, its own
    heading, mhat from the hover, take off to 2.5 m (the height PX4 SIH sank from)."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    gcs_base = free_udp_port_block(4)
    data["mission"]["duration_s"] = duration_s
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_port": bind_base + k}
        v["initial"]["position_enu_m"][2] = 0.0
        v["initial"]["attitude_rpy_rad"] = [0.0, 0.0, YAWS_ENU_RAD[k]]
        v["estimates"]["mhat"] = "from_hover"
    data["fly"].update(start="takeoff", takeoff_altitude_m=2.5)
    # the formation starts at 2.5 m, where PX4 SIH sank from: no go-to-start (the start
    # positions are on the ground)
    data["fly"]["go_to_start"] = {"enabled": False}
    data["fly"]["geofence"]["min_enu_m"][2] = 0.5
    data["emulator"] = {"autopilot": "px4"}  # each vehicle's own origin, where it boots
    path = tmp / "team.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def airborne_yaw_error_deg(tlog: Path, yaw0_ned_rad: dict[int, float]) -> dict[int, float]:
    """Per sysid, the largest |reported yaw - start yaw| while more than 1 m up [deg]."""
    worst = dict.fromkeys(yaw0_ned_rad, 0.0)
    height: dict[int, float] = {}
    conn = mavutil.mavlink_connection(str(tlog))
    while (m := conn.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE_QUATERNION"])) is not None:
        sysid = m.get_srcSystem()
        if sysid not in worst:
            continue
        if m.get_type() == "LOCAL_POSITION_NED":
            height[sysid] = -m.z
        elif height.get(sysid, 0.0) > 1.0:
            yaw = math.atan2(2 * (m.q1 * m.q4 + m.q2 * m.q3), 1 - 2 * (m.q3 ** 2 + m.q4 ** 2))
            err = (yaw - yaw0_ned_rad[sysid] + math.pi) % (2 * math.pi) - math.pi
            worst[sysid] = max(worst[sysid], abs(math.degrees(err)))
    return worst


def test_px4_team_from_the_ground_attitude_mode_mass_from_the_hover_no_sink(tmp_path):
    bind_base = free_udp_port_block(4)
    team = ground_team(tmp_path, bind_base, duration_s=30.0)
    with emulators(team, bind_base, tmp_path):
        gcs = Gcs(team, tmp_path / "run", "--mode", "attitude")
        code, out = gcs.finish(timeout_s=240)
    log = gcs.log_path.read_text()
    # THEN the flight completes (no geofence breach at the formation start, as PX4 SIH had)
    assert code == 0, out + log[-3000:]
    report = gcs.report()
    truth = {v["id"]: v["plant"]["mass_kg"]
             for v in yaml.safe_load(team.read_text())["vehicles"]}
    # AND each initial mass came from the hover, within 5 % of the vehicle's mass, with
    # Proposition 2 printed
    hover = report["extra"]["hover_estimates"]
    assert sorted(int(k) for k in hover) == sorted(truth)
    for vid, est in hover.items():
        assert est["mass_kg"] == pytest.approx(truth[int(vid)], rel=0.05), (vid, est)
        assert f"vehicle {vid} (sysid {vid}): hover thrust" in log
    assert log.count("Proposition 2: mhat(0) >= (phi(0) - 1) mbar / alpha_m") == 4
    # AND the formation converged to the px4 personality's noise: tens of cm, not the metres of
    # a sinking or diverging team (measured from 20 s: mean 0.43 m on a quiet machine, 0.61 m
    # beside two busy loops; max 0.6-0.7 m)
    t = np.array(report["t_s"])
    fe = np.array(report["formation_error_m"], dtype=float)
    assert np.nanmax(fe[t >= 20.0]) < 1.0
    assert np.nanmean(fe[t >= 20.0]) < 0.8
    # AND no vehicle turned to the paper's heading (east: 23-115 deg from these starts): each
    # kept the one it booted with. Not within the real-autopilot issue's 5 deg: on the px4
    # personality the attitude mode oscillates (docs/gcs.md, "Open points"), and the heading
    # wanders by 2-4 deg on average, 10.7 deg at most (measured); 15 deg bounds that wander
    yaw0 = {k + 1: math.pi / 2 - y for k, y in enumerate(YAWS_ENU_RAD)}  # ENU -> NED yaw
    worst = airborne_yaw_error_deg(tmp_path / "run" / "flight.tlog", yaw0)
    assert max(worst.values()) < 15.0, worst


def test_ardupilot_pair_attitude_mode_with_the_thrust_equivalent_hover_mass(tmp_path):
    ports = gcs_ports()
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "ardupilot2-attitude"
    data["vehicles"] = data["vehicles"][:2]
    data["graph"]["edges"] = [[1, 2]]
    data["mission"]["duration_s"] = 20.0
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": ports[k], "learn_remote": True}
        v["estimates"]["mhat"] = "from_hover"
        # starts 5 m lower than Scenario I's (4 and 6 m up): a shorter climb and landing
        v["initial"]["position_enu_m"][2] -= 5.0
    team = tmp_path / "team.yaml"
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    with copters(tmp_path, ports, 8, 8):
        proc = subprocess.run(
            [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out",
             str(tmp_path / "run"), "--no-figures", "--status", "off", "--log-level", "INFO",
             "--mode", "attitude"],
            stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=200,
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-3000:]
    import json

    report = json.loads((tmp_path / "run" / "report.json").read_text())
    # THEN the hover mass is the thrust-equivalent mass m / 1.069 (ArduPilot's battery and
    # air-density compensation, docs/gcs.md "Initial mass"), within 5 %
    from vehicle_emulator.config.personality import PERSONALITIES

    scale = PERSONALITIES["ardupilot"].dynamics.thrust_scale
    for vid, est in report["extra"]["hover_estimates"].items():
        mass = data["vehicles"][int(vid) - 1]["plant"]["mass_kg"]
        assert est["mass_kg"] == pytest.approx(mass / scale, rel=0.05), (vid, est)
    t = np.array(report["t_s"])
    fe = np.array(report["formation_error_m"], dtype=float)
    assert np.nanmax(fe[t >= 15.0]) < 0.1
