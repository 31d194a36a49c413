"""A new user's first run: empty compile cache, vehicles that start late or never, `--emulators`.

Real processes over 127.0.0.1 UDP: `vehicle-emu` and `gcs` as a user starts them. The compile
cache is emptied by pointing NUMBA_CACHE_DIR at a new folder, exactly what a fresh machine has.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml
from pymavlink import mavutil
from stall_relay import StallRelay
from test_fly_emulator import Gcs, emulators, team_file

from benchmarks.make_grid import team_text
from flightkit.fleet_protocol import READY_PREFIX
from tests.harness import free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]


@pytest.fixture
def empty_cache(tmp_path, monkeypatch) -> Path:
    """A new, empty numba cache for every process this test starts."""
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    return cache


def test_manual_path_on_an_empty_cache_fleet_and_gcs_started_together(tmp_path, empty_cache):
    # GIVEN nothing compiled, WHEN `vehicle-emu --fleet` and `gcs fly` start at the same moment
    # (no --mode: the file's fly.mode, auto, while its controller.mode is gcs sim's actuators)
    base = free_udp_port_block(4)
    team = team_file(tmp_path, base, duration_s=3.0)
    with emulators(team, base, tmp_path) as procs:
        gcs = Gcs(team, tmp_path / "run", "--end-action", "hold")
        code, out = gcs.finish(240)
        assert procs[0].poll() is None, "the fleet died"
    err = gcs.log_path.read_text()
    emu = (tmp_path / "emu0.log").read_text()
    # THEN both say they compile (first run only), and the flight waits for it and succeeds
    assert code == 0, err[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in out
    # auto chose rates on the vehicles' declared response, and said so before connecting
    assert ("gcs fly: mode rates (auto: the first of rates, attitude whose loops pass on every "
            "vehicle with fly.rates's gains at link delay 10 ms)") in err
    assert json.loads((tmp_path / "run" / "report.json").read_text())["extra"]["mode"] == "rates"
    assert "gcs: compiling the control law (first run" in err
    assert "vehicle-emu: compiling the emulator physics (first run" in emu
    assert "vehicle-emu: compiled the emulator physics in" in emu
    # and the compiled code is cached: the next start compiles nothing and says nothing
    again = subprocess.run([sys.executable, "-m", "vehicle_emulator", "--compile-only"],
                           capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and "compiling" not in again.stderr


@pytest.mark.timeout(1200)  # a compile from nothing, then four flights, on a busy machine
def test_gcs_compile_leaves_every_program_ready(tmp_path, empty_cache):
    # GIVEN `gcs compile` (what `make install` runs) on an empty cache
    first = subprocess.run([sys.executable, "-m", "gcs.cli", "compile"], capture_output=True,
                           text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    for part in ("the control law", "the simulator", "the emulator physics"):
        assert f"compiling {part}" in first.stderr and f"compiled {part} in" in first.stderr
    assert len(list(empty_cache.rglob("*.nbi"))) > 20
    # WHEN the programs run after it THEN none of them compiles again
    sim = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "sim", "--team", str(Path("configs/square4.yaml")),
         "--duration-s", "1", "--no-figures", "--quiet", "--out", str(tmp_path / "sim")],
        capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert sim.returncode == 0, sim.stderr
    assert "compiling" not in sim.stderr
    emu = subprocess.run([sys.executable, "-m", "vehicle_emulator", "--compile-only"],
                         capture_output=True, text=True, timeout=120)
    assert emu.returncode == 0 and "compiling" not in emu.stderr
    # AND fleets of 1, 4 (one of every personality) and 16 vehicles fly on a copy of that cache
    # without compiling anything after their ready lines, on either side: numba's compile
    # events, which both programs watch from their ready line on, tell. The three fly at once,
    # each on its own ports and cache copy: what they compile, not how they fly, is the point
    cases = ((1, 1, ("px4",)), (2, 2, ("px4", "ardupilot", "nominal", "px4")),
             (4, 4, ("px4",)))

    def fly_case(case: tuple[int, int, tuple[str, ...]]) -> dict[str, list[str]]:
        rows, cols, autopilots = case
        name = f"{rows}x{cols}-{'-'.join(sorted(set(autopilots)))}"
        cache = tmp_path / f"cache-{name}"
        shutil.copytree(empty_cache, cache)
        return _compiled_after_ready(tmp_path / f"fly-{name}", rows, cols, list(autopilots), cache)

    with ThreadPoolExecutor(max_workers=len(cases)) as pool:
        lates = list(pool.map(fly_case, cases))
    for case, late in zip(cases, lates, strict=True):
        assert late == {"vehicle-emu": [], "gcs fly": []}, case


def _compiled_after_ready(tmp: Path, rows: int, cols: int, autopilots: list[str],
                          cache: Path) -> dict[str, list[str]]:
    """Fly a rows x cols grid team (vehicle i of personality autopilots[i % len]) for 2 s with
    `vehicle-emu --fleet` and `gcs fly` on numba cache `cache`; what each compiled after its
    ready line."""
    tmp.mkdir()
    data = yaml.safe_load(team_text(rows, cols, None))
    n = rows * cols
    vehicle_base, gcs_base = free_udp_port_block(n), free_udp_port_block(n)
    data["mission"]["duration_s"] = 2.0
    for k, v in enumerate(data["vehicles"]):
        kind = autopilots[k % len(autopilots)]
        v["emulator"] = {"autopilot": kind}
        # ArduPilot SITL sends from an ephemeral port (learned from its first message)
        v["link"] = {"local_port": gcs_base + k, "remote_port": vehicle_base + k,
                     **({"learn_remote": True} if kind == "ardupilot" else {})}
    team = tmp / "team.yaml"
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONUNBUFFERED": "1"}
    stats = tmp / "emu.json"
    with open(tmp / "emu.log", "w") as emu_log:
        fleet = subprocess.Popen(
            [sys.executable, "-m", "vehicle_emulator", "--fleet", "--team", str(team),
             *(["--param", "GUID_OPTIONS=8"] if "ardupilot" in autopilots else []),
             "--stats-json", str(stats), "--log-level", "WARNING"],
            stdout=subprocess.PIPE, stderr=emu_log, text=True, env=env)
        try:
            assert fleet.stdout is not None
            assert fleet.stdout.readline().startswith(READY_PREFIX), (tmp / "emu.log").read_text()
            gcs = subprocess.run(
                [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out",
                 str(tmp / "run"), "--no-figures", "--status", "plain"],
                capture_output=True, text=True, env=env, timeout=300)
        finally:
            fleet.terminate()
            fleet.wait(timeout=30)
    # the flight itself may end either way on a loaded machine; what it compiled is the point
    late = {"vehicle-emu": json.loads(stats.read_text())["compiled_after_ready"]}
    report = tmp / "run" / "report.json"
    late["gcs fly"] = (json.loads(report.read_text())["extra"]["compiled_after_ready"]
                       if report.exists() else [])
    for prog, text in (("vehicle-emu", (tmp / "emu.log").read_text()), ("gcs fly", gcs.stderr)):
        late[prog] += [line for line in text.splitlines() if "after ready" in line
                       and line not in late[prog]]
    return late


def test_a_vehicle_heard_then_silent_during_configure_is_waited_for_not_failed(tmp_path):
    # GIVEN one vehicle whose program stops for 4 s right after its first HEARTBEAT reached the
    # ground station (as the fleet did while compiling after its ready line): the ground
    # station's stream requests go unanswered, and nothing else arrives either
    subprocess.run([sys.executable, "-m", "vehicle_emulator", "--compile-only"], check=True,
                   timeout=600)  # so that the vehicle boots in the connect window
    data = yaml.safe_load(team_text(1, 1, None))
    data["mission"]["duration_s"] = 2.0
    vehicle_port, gcs_port = free_udp_port_block(1), free_udp_port_block(1)
    with StallRelay(gcs_port, vehicle_port, stall_s=4.0) as relay:
        gcs_team, emu_team = tmp_path / "gcs.yaml", tmp_path / "emu.yaml"
        for path, local, remote in ((gcs_team, gcs_port, relay.gcs_side),
                                    (emu_team, relay.vehicle_side, vehicle_port)):
            data["vehicles"][0]["link"] = {"local_port": local, "remote_port": remote}
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        gcs = Gcs(gcs_team, tmp_path / "run", "--mode", "rates", "--connect-timeout-s", "30")
        gcs.wait_for("waiting for", 60)  # listening before the vehicle boots
        with emulators(emu_team, vehicle_port, tmp_path, n=1):
            code, out = gcs.finish(240)
        err = gcs.log_path.read_text()
        assert relay.stalled_at is not None and relay.held > 0, (relay.held, err[-2000:])
    # THEN the ground station says the vehicle went silent and waits (bounded), instead of
    # failing its stream request after 1.5 s; once the vehicle speaks, it asks again and flies
    assert ("vehicle 1 (sysid 1): MAV_CMD_SET_MESSAGE_INTERVAL (511) unanswered: heard at "
            in err), err[-3000:]
    assert "silent since; waiting up to 30 s for it to speak" in err
    assert "vehicle 1 (sysid 1): heard again after " in err
    assert "configure failed" not in err
    assert code == 0, err[-3000:]
    assert "gcs fly: done: formation complete (exit 0)" in out


def test_connect_names_who_was_heard_and_fails_with_a_line_per_missing_vehicle(tmp_path):
    # GIVEN vehicles 1 and 3 running, nothing at vehicle 2's port, and a stranger (sysid 9)
    # sending HEARTBEATs where vehicle 4 is expected
    base = free_udp_port_block(4)
    team = team_file(tmp_path, base, duration_s=3.0)
    import yaml

    ports = [v["link"]["local_port"] for v in yaml.safe_load(team.read_text())["vehicles"]]
    stranger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{ports[3]}", source_system=9,
                                          source_component=1)
    with emulators(team, base, tmp_path, separate=True, n=3) as procs:
        procs[1].terminate()  # vehicle 2 is not running
        procs[1].wait(timeout=10)
        gcs = Gcs(team, tmp_path / "run", "--mode", "rates", "--connect-timeout-s", "8")
        end = time.monotonic() + 60
        while gcs.proc.poll() is None and time.monotonic() < end:
            stranger.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_QUADROTOR,
                                        mavutil.mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
            time.sleep(0.2)  # a 5 Hz heartbeat source, as a vehicle would send
        code, _ = gcs.finish(30)
    err = gcs.log_path.read_text()
    # THEN while connecting, the status says who was heard and where it waits for the others
    assert "heard 2/4 (1, 3); waiting for vehicle 2 (sysid 2) on udp 127.0.0.1:" in err
    assert f"vehicle 4 (sysid 4) on udp 127.0.0.1:{ports[3]} [heard sysid 9 there instead]" in err
    # AND it fails after the timeout with one line per missing vehicle, having commanded nobody
    assert code == 1
    assert ("gcs fly: ABORTED: no link to 2 of 4 vehicles within 8 s (nothing was commanded) "
            "(exit 1)") in err
    assert (f"  vehicle 2 (sysid 2): nothing heard on udp 127.0.0.1:{ports[1]}; is it running, "
            "and does it send there?") in err
    assert (f"  vehicle 4 (sysid 4): only sysid 9 was heard on udp 127.0.0.1:{ports[3]}; check "
            "the team file's sysid and link for this vehicle") in err
    tlog = mavutil.mavlink_connection(str(tmp_path / "run" / "flight.tlog"))
    commands = []
    while (msg := tlog.recv_match(type=["COMMAND_LONG", "SET_ATTITUDE_TARGET"])) is not None:
        commands.append(msg.get_type())
    assert commands == []


def _gcs_fly_emulators(team: Path, out: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out", str(out),
         "--no-figures", "--status", "plain", "--mode", "rates", "--emulators", *args],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})


def test_emulators_flag_reports_a_fleet_that_dies_before_it_is_ready(tmp_path):
    # GIVEN vehicle 1's emulator port is taken, so the fleet cannot start
    base = free_udp_port_block(4)
    team = team_file(tmp_path, base, duration_s=3.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as squatter:
        squatter.bind(("127.0.0.1", base))
        proc = _gcs_fly_emulators(team, tmp_path / "run")
        out, _ = proc.communicate(timeout=120)
    # THEN gcs fly says the fleet died, with its status and its own message, and exits 2
    assert proc.returncode == 2, out
    assert "Address already in use" in out
    assert (f"gcs fly: the emulator fleet (vehicle-emu --fleet --team {team}) exited with "
            "status 3 before it was ready") in out


def test_emulators_flag_reports_a_fleet_that_dies_during_the_flight(tmp_path):
    base = free_udp_port_block(4)
    team = team_file(tmp_path, base, duration_s=30.0)
    proc = _gcs_fly_emulators(team, tmp_path / "run")
    lines: list[str] = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("[formation]"):
            break
    # WHEN the fleet process is killed mid-formation
    children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True)
    pids = [int(p) for p in children.stdout.split()]
    assert len(pids) == 1, children
    os.kill(pids[0], signal.SIGKILL)
    out, _ = proc.communicate(timeout=120)
    text = "".join(lines) + out
    # THEN gcs fly reports it at once and the flight ends aborted on the lost links
    assert f"the emulator fleet (pid {pids[0]}) exited with status -9 during the flight" in text
    assert proc.returncode == 1, text[-3000:]
    assert "gcs fly: ABORTED:" in text and "link" in text
