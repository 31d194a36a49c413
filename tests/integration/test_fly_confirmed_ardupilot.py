"""`gcs fly` judged by what ArduPilot Copters report (issue 9, point 1): the real `gcs` CLI
against real `vehicle-emu --autopilot ardupilot` processes over 127.0.0.1 UDP, each failure of the
issue reproduced, its message pinned; the PX4 side is test_fly_confirmed.py (split from it so that
`pytest -n 2 --dist loadfile` can run the two on different workers).

One process per copter as SITL runs it (as in test_fly_ardupilot.py): an ephemeral source port the
team file's link learns, no forced bind, no message-intervals file; here the copters boot on a
quarter of the recorded timeline (EMU_BOOT_SCALE=0.25: no position estimate, so no
LOCAL_POSITION_NED and no GUIDED arming, for ~10.4 s) or on the real one.
Flights are short (formation 2 s): what is tested is the sequence, not the figures.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from tests.harness import free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]

ROOT = Path(__file__).resolve().parents[2]
COMMAND_LINE = re.compile(r"command (\d+) \(([^)]*)\) -> (\w+)")


@contextlib.contextmanager
def copters(tmp: Path, n: int = 2, boot_scale: float = 0.25) -> Iterator[list]:
    """`vehicle-emu --autopilot ardupilot` per vehicle, GUID_OPTIONS 8, booting on
    `boot_scale` of the recorded timeline (0.25: GUIDED armable after ~10.4 s), on ArduPilot's
    ephemeral port, each sending to a free GCS port (its `remote_port`)."""
    with contextlib.ExitStack() as stack:
        yield [stack.enter_context(run_emulator(
            ["--id", str(k + 1), "--autopilot", "ardupilot", "--param",
             f"EMU_BOOT_SCALE={boot_scale}", "--param", "GUID_OPTIONS=8"],
            remote_port=free_udp_port(), log_dir=str(tmp), bind=False)) for k in range(n)]


def ardupilot_team(tmp: Path, emus: list, fly: dict | None = None) -> Path:
    """square4's first vehicles (one edge if two), rates mode, 2 s, linked to the copters, their
    start positions 5 m lower (4 and 6 m up: a shorter climb and landing, the same sequence)."""
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = "ardupilot2"
    data["vehicles"] = data["vehicles"][:len(emus)]
    data["graph"]["edges"] = [[1, 2]] if len(emus) == 2 else []
    data["mission"]["duration_s"] = 2.0
    data["fly"].update(fly or {})
    for v, emu in zip(data["vehicles"], emus, strict=True):
        v["link"] = {"local_port": emu.remote_port, "learn_remote": True}
        v["initial"]["position_enu_m"][2] -= 5.0
    path = tmp / "team.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def ardupilot_fly(team: Path, out: Path) -> tuple[int, str, str]:
    proc = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out", str(out),
         "--no-figures", "--status", "off", "--log-level", "INFO", "--mode", "rates"],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=150,
        env={**os.environ, "PYTHONUNBUFFERED": "1"}, check=False)
    return proc.returncode, proc.stdout, proc.stderr


def received(emu, since: int = 0) -> list[tuple[str, float, str]]:
    """(command, param1 or mode, result) of what the copter was sent, from its log."""
    out = []
    for cmd, params, result in COMMAND_LINE.findall(emu.log_text()[since:]):
        p = [float(x) for x in params.split(", ")]
        if cmd == "176":
            out.append(("mode", p[1], result))
        elif cmd == "400":
            out.append(("arm" if p[0] == 1.0 else "disarm", p[1], result))
        elif cmd == "22":
            out.append(("takeoff", p[6], result))
    return out


def test_ardupilot_that_is_not_ready_in_time_fails_quoting_its_statustext(tmp_path: Path) -> None:
    # GIVEN a copter at the real boot timeline (a position estimate only after 41.6 s) and a 5 s
    # fly.arm_timeout_s
    with copters(tmp_path, n=1, boot_scale=1.0) as emus:
        team = ardupilot_team(tmp_path, emus, fly={"arm_timeout_s": 5.0})
        code, out, err = ardupilot_fly(team, tmp_path / "run")
        sent = received(emus[0])
    # THEN exit 1 after 5 s, naming what is missing and quoting the vehicle's latest STATUSTEXT
    assert code == 1, err[-3000:]
    assert re.search(r"gcs fly: ABORTED: vehicle 1 \(sysid 1\): LOCAL_POSITION_NED at 0\.0 Hz, "
                     r"need >= 50 Hz \(asked 100\); vehicle 1 \(sysid 1\): no valid "
                     r"position/velocity; vehicle 1 \(sysid 1\): not ready within 5 s "
                     r"\(fly\.arm_timeout_s\); latest STATUSTEXT: \w+ \"[^\"]+\"", err), err[-2000:]
    # AND it was never commanded (no mode change, no arming)
    assert sent == [], sent
