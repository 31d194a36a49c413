"""vehicle-emu command line: help, fleet mode on real UDP, team-file errors, clean exit."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink

from flightkit.sched import EMU_RAISED_NICE, EMU_RT_PRIORITY
from tests.harness import (
    clients_on_port_block,
    free_udp_port,
    free_udp_port_block,
    run_emulator,
)
from vehicle_emulator.physics.geodesy import HOME_ALT_M, HOME_LAT_DEG, HOME_LON_DEG, geodetic_to_enu

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]
EMU = [sys.executable, "-m", "vehicle_emulator"]


def test_console_script_help():
    exe = shutil.which("vehicle-emu") or str(Path(sys.executable).parent / "vehicle-emu")
    out = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    assert "--fleet" in out.stdout and "--team" in out.stdout


def test_help_says_what_it_emulates_and_shows_examples():
    # GIVEN `vehicle-emu --help`
    out = subprocess.run([*EMU, "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    # THEN each personality is named with what it stands for, one per line
    for pattern in (r"^  px4 +\(default\) behaves like PX4 v1\.16\.0 SITL",
                    r"^  ardupilot +behaves like ArduCopter 4\.7\.0-dev SITL",
                    r"^  nominal +the paper's nominal model"):
        assert re.search(pattern, out.stdout, re.MULTILINE), out.stdout
    # AND examples for one vehicle, a fleet and another personality
    for example in ("vehicle-emu --id 1 ", "vehicle-emu --fleet --team configs/square4.yaml\n",
                    "vehicle-emu --fleet --team configs/square4.yaml --autopilot ardupilot"):
        assert f"\n  {example}" in out.stdout, out.stdout


def test_fleet_runs_every_vehicle_on_its_own_endpoint_and_exits_cleanly(tmp_path):
    # GIVEN the Scenario I team (4 vehicles in the air) as one --fleet process
    clients = clients_on_port_block(4)
    remote_base = clients[0].port
    bind_base = free_udp_port_block(4)
    log = open(tmp_path / "fleet.log", "w")
    proc = subprocess.Popen(
        [
            *EMU,
            "--fleet",
            "--team",
            str(ROOT / "configs/square4.yaml"),
            "--bind-base",
            str(bind_base),
            "--remote-base",
            str(remote_base),
        ],
        stdout=log,
        stderr=log,
    )
    try:
        # THEN each vehicle speaks from its own sysid to its own remote port, armed in Hold
        for k, c in enumerate(clients):
            hb = c.wait("HEARTBEAT", 60)
            assert hb.get_srcSystem() == k + 1 and hb.base_mode & 128
            assert hb.custom_mode == (4 << 16) | (3 << 24)
        # its local position from its own EKF origin, the ground point below its team-file
        # start (4, 4, 9) m ENU (the emulator's default, as real vehicles): 9 m up, NED
        pos = clients[0].wait("LOCAL_POSITION_NED", 3)
        assert (pos.x, pos.y, pos.z) == pytest.approx((0.0, 0.0, -9.0), abs=0.05)
        # and every vehicle answers commands on its own port
        for c in clients:
            assert c.command_acks(176, 1 | 128, 3, 0, count=2) == [0, 0]  # PX4 v1.16.0: twice
        # WHEN SIGTERM THEN a clean exit
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        assert time.monotonic() - t0 < 5
    finally:
        if proc.poll() is None:
            proc.kill()
        log.close()
        for c in clients:
            c.close()
    assert "Traceback" not in (tmp_path / "fleet.log").read_text()


def test_fleet_vehicles_with_own_origins_report_local_positions_from_them(tmp_path):
    # GIVEN the Scenario I team with the real-vehicle default, each vehicle's own EKF origin
    data = yaml.safe_load((ROOT / "configs/square4.yaml").read_text())
    data["emulator"] = {"origin": "own"}
    team = tmp_path / "team.yaml"
    team.write_text(yaml.safe_dump(data))
    clients = clients_on_port_block(4)
    proc = subprocess.Popen(
        [*EMU, "--fleet", "--team", str(team), "--bind-base", str(free_udp_port_block(4)),
         "--remote-base", str(clients[0].port)],
        stdout=subprocess.DEVNULL, stderr=open(tmp_path / "fleet.log", "w"),  # noqa: SIM115
    )
    try:
        for c, v in zip(clients, data["vehicles"], strict=True):
            x, y, z = v["initial"]["position_enu_m"]
            # THEN LOCAL_POSITION_NED is zero on the ground below where the vehicle booted
            pos = c.wait("LOCAL_POSITION_NED", 60)
            assert (pos.x, pos.y, pos.z) == pytest.approx((0.0, 0.0, -z), abs=0.05)
            # AND GPS_GLOBAL_ORIGIN places that origin in the team frame, on the WGS-84
            # ellipsoid; GLOBAL_POSITION_INT the vehicle
            c.send(mavlink.MAVLink_command_long_message(c.target_system, 1, 512, 0, 49, 0, 0, 0,
                                                        0, 0, 0))
            origin = c.wait("GPS_GLOBAL_ORIGIN", 3)
            enu = geodetic_to_enu(origin.latitude * 1e-7, origin.longitude * 1e-7,
                                  origin.altitude * 1e-3, HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)
            assert enu == pytest.approx((x, y, 0.0), abs=0.02)
            gp = c.wait("GLOBAL_POSITION_INT", 3)
            enu = geodetic_to_enu(gp.lat * 1e-7, gp.lon * 1e-7, gp.alt * 1e-3, HOME_LAT_DEG,
                                  HOME_LON_DEG, HOME_ALT_M)
            assert enu == pytest.approx((x, y, z), abs=0.05)
    finally:
        proc.terminate()
        proc.wait(10)
        for c in clients:
            c.close()


def test_sigint_stops_a_single_vehicle_cleanly(tmp_path):
    port = free_udp_port()
    proc = subprocess.Popen(
        [
            *EMU,
            "--id",
            "2",
            "--bind",
            f"127.0.0.1:{free_udp_port()}",
            "--remote",
            f"127.0.0.1:{port}",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    from tests.harness import MavClient

    client = MavClient(port, target_system=2)
    try:
        client.wait("HEARTBEAT", 60)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
        assert "stopped after" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
        client.close()


def test_bad_team_file_names_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicles:\n  - id: 1\n    plant: {mass_kg: -1.0}\n")
    out = subprocess.run(
        [*EMU, "--id", "1", "--team", str(bad)], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2
    assert "vehicles[0].plant.mass_kg: expected > 0, got -1.0" in out.stderr
    out = subprocess.run(
        [*EMU, "--id", "9", "--team", str(ROOT / "configs/square4.yaml")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0 and "no vehicle with id 9" in out.stderr


def test_fleet_behind_one_gcs_port_with_requested_streams(tmp_path):
    # GIVEN three vehicles whose links all send to ONE ground-station port (a 240-vehicle team's
    # layout), each binding its own port, run with --streams requested
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.5)
    gcs_port = gcs.getsockname()[1]
    bind_base = free_udp_port_block(3)
    vehicles = [{"id": k + 1, "initial": {"position_enu_m": [3.0 * k, 0.0, 10.0]},
                 "link": {"local_port": gcs_port, "remote_host": "127.0.0.1",
                          "remote_port": bind_base + k}} for k in range(3)]
    team = tmp_path / "team.yaml"
    team.write_text(yaml.safe_dump({"vehicles": vehicles}))
    proc = subprocess.Popen([*EMU, "--fleet", "--team", str(team), "--streams", "requested"],
                            stdout=subprocess.DEVNULL, stderr=open(tmp_path / "fleet.log", "w"))  # noqa: SIM115
    parser = mavlink.MAVLink(None)
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)

    def receive(seconds: float) -> list[tuple[int, object]]:
        out, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data, addr = gcs.recvfrom(4096)
            except TimeoutError:
                continue
            out += [(addr[1], m) for m in parser.parse_buffer(data) or []]
        return out

    try:
        # THEN each vehicle's HEARTBEAT comes from its own port with its own sysid, and no
        # other stream before one is asked for
        got: list[tuple[int, object]] = []
        deadline = time.monotonic() + 60
        while len({m.get_srcSystem() for _, m in got if m.get_type() == "HEARTBEAT"}) < 3:
            assert time.monotonic() < deadline, "not every vehicle heard"
            got += receive(0.5)
        got += receive(1.5)
        for port, m in got:
            assert port == bind_base + m.get_srcSystem() - 1
        assert {m.get_type() for _, m in got} <= {"HEARTBEAT", "STATUSTEXT", "GPS_GLOBAL_ORIGIN"}
        # WHEN the ground station asks each vehicle, from the shared port, for
        # ATTITUDE_QUATERNION at 50 Hz and streams rates setpoints to it
        for k in range(3):
            cmd = mavlink.MAVLink_command_long_message(k + 1, 1, 511, 0, 31, 20_000, 0, 0, 0, 0, 0)
            gcs.sendto(cmd.pack(mav), ("127.0.0.1", bind_base + k))
        for _ in range(10):
            for k in range(3):
                sp = mavlink.MAVLink_set_attitude_target_message(
                    0, k + 1, 1, 128, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.5)
                gcs.sendto(sp.pack(mav), ("127.0.0.1", bind_base + k))
        got = receive(1.0)
        # THEN every vehicle ACKs (to the shared port) and streams what was asked, and only that
        acks = {m.get_srcSystem(): m.result for _, m in got if m.get_type() == "COMMAND_ACK"}
        assert acks == {1: 0, 2: 0, 3: 0}
        for k in range(3):
            n = sum(1 for _, m in got
                    if m.get_type() == "ATTITUDE_QUATERNION" and m.get_srcSystem() == k + 1)
            assert 35 <= n <= 55, (k, n)
        assert {m.get_type() for _, m in got} <= {"HEARTBEAT", "COMMAND_ACK",
                                                   "ATTITUDE_QUATERNION", "STATUSTEXT"}
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        gcs.close()
    assert "Traceback" not in (tmp_path / "fleet.log").read_text()


def test_what_start_up_built_is_out_of_the_collectors_sight_for_the_run(tmp_path):
    # GIVEN a fleet run for 2 simulated seconds with its figures written, sending to ports this
    # test holds and never answers (the default remotes, 14540-14543, are any ground station's
    # on the machine: one listening there answers the fleet, and the fleet then reads its input)
    stats = tmp_path / "stats.json"
    sinks = clients_on_port_block(4)
    try:
        out = subprocess.run(
            [*EMU, "--fleet", "--team", str(ROOT / "configs/square4.yaml"), "--duration", "2",
             "--bind-base", str(free_udp_port_block(4)), "--remote-base", str(sinks[0].port),
             "--stats-json", str(stats)],
            capture_output=True, text=True, timeout=90)
    finally:
        for sink in sinks:
            sink.close()
    assert out.returncode == 0, out.stderr
    # THEN the fleet, the libraries and the kernels were frozen before the run (a full
    # collection walks only what the run allocated), and the run's collections are counted
    figures = json.loads(stats.read_text())
    assert figures["gc_frozen_objects"] > 20_000
    assert len(figures["gc_collections"]) == 3
    assert all(isinstance(n, int) and n >= 0 for n in figures["gc_collections"])
    # AND with nothing sent to it, no input backlog and no setpoint superseded (server.py)
    assert figures["deepest_backlog"] == 0
    assert [v["setpoints_superseded"] for v in figures["by_vehicle"]] == [0, 0, 0, 0]


def test_the_vehicles_run_at_the_scheduling_they_asked_for(tmp_path):
    # GIVEN one vehicle with the default --scheduling auto, its figures written at exit
    stats = tmp_path / "stats.json"
    proc = subprocess.Popen(
        [*EMU, "--id", "1", "--bind", f"127.0.0.1:{free_udp_port()}", "--remote",
         f"127.0.0.1:{free_udp_port()}", "--stats-json", str(stats)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # WHEN it is ready (the priority is asked for before the links open)
        assert proc.stdout is not None and proc.stdout.readline().startswith("vehicle-emu: ready:")
        fifo = os.sched_getscheduler(proc.pid) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
        priority = os.sched_getparam(proc.pid).sched_priority
        nice = os.getpriority(os.PRIO_PROCESS, proc.pid)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
    detail = json.loads(stats.read_text())["scheduling"]
    # THEN the process runs at what the figures and the log say it got
    assert proc.stderr is not None and detail in proc.stderr.read()
    if detail.startswith("real-time"):
        assert fifo == os.SCHED_FIFO and priority == EMU_RT_PRIORITY
    elif detail.startswith("raised"):
        assert fifo != os.SCHED_FIFO and nice == EMU_RAISED_NICE
    else:
        assert detail.startswith("normal scheduling: ") and fifo != os.SCHED_FIFO
    if os.geteuid() == 0:  # auto: raised, never real-time (sched.EMULATOR)
        assert detail == f"raised priority: nice {EMU_RAISED_NICE}"


@pytest.mark.skipif(not (os.geteuid() == 0 and shutil.which("setpriv")),
                    reason="needs root to run the emulator as an unprivileged user")
def test_a_refused_scheduling_asked_for_by_name_is_a_one_line_error_before_any_link():
    # GIVEN a user the operating system refuses real-time scheduling (nobody: no capability, no
    # rtprio limit), with a numba cache it may write (its modules' decorators need one; pytest's
    # tmp_path is private to the user running the tests)
    cache = Path(tempfile.mkdtemp(prefix="numba-nobody-"))
    cache.chmod(0o777)
    port = free_udp_port()
    try:
        out = subprocess.run(
            ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "--inh-caps=-all",
             *EMU, "--id", "1", "--bind", f"127.0.0.1:{port}", "--remote",
             f"127.0.0.1:{free_udp_port()}", "--scheduling", "realtime"],
            capture_output=True, text=True, timeout=90,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
                 "NUMBA_CACHE_DIR": str(cache)})
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    # THEN it exits 2 with one line naming the option and how to grant it, before it is ready
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.startswith("vehicle-emu: ")]
    assert lines == [f"vehicle-emu: --scheduling realtime: SCHED_FIFO refused (Operation not "
                     f"permitted); grant it with root, `sudo setcap cap_sys_nice+ep "
                     f"\"$(readlink -f .venv/bin/python)\"`, or a nice limit of "
                     f"{EMU_RAISED_NICE} (an rtprio limit of {EMU_RT_PRIORITY} for realtime; "
                     f"docs/emulator.md, \"Scheduling\")"], out.stderr
    assert "ready" not in out.stdout


def test_a_failed_wait_on_an_emulator_names_its_state_and_log(tmp_path):
    # GIVEN an emulator that refuses its arguments and exits
    with (pytest.raises(TimeoutError) as failed,
          run_emulator(["--id", "1", "--no-such-option"], log_dir=str(tmp_path)) as emu):
        emu.proc.wait(30)
        # WHEN the test's wait for it fails
        raise TimeoutError("no HEARTBEAT within 1 s")
    # THEN the error says the emulator exited, with what, and ends with the log's last lines
    note = "\n".join(failed.value.__notes__)
    assert f"pid {emu.proc.pid} exited with 2" in note
    assert "--no-such-option" in note and emu.log_path in note
