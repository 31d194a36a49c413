"""`gcs fly` refuses to start, with one line and exit 2, when it cannot open what the team file
asks for (a real process, real sockets on 127.0.0.1)."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import yaml

from tests.harness import free_udp_port_block

ROOT = Path(__file__).resolve().parents[2]


def test_a_gcs_port_another_program_holds_is_a_setup_error_naming_vehicle_and_port(tmp_path):
    # GIVEN square4 on free ports, and another program bound to vehicle 3's GCS port
    base = free_udp_port_block(8)
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    for k, vehicle in enumerate(data["vehicles"]):
        vehicle["link"] = {"local_port": base + k, "remote_port": base + 4 + k}
    team = tmp_path / "team.yaml"
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", base + 2))
        # WHEN gcs fly is run THEN exit 2, no traceback, one line naming the vehicle and port
        fly = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "--team", str(team),
                              "--out", str(tmp_path / "run"), "--status", "off"],
                             capture_output=True, text=True, timeout=120, check=False)
    assert fly.returncode == 2, fly.stderr
    assert "Traceback" not in fly.stderr
    errors = [line for line in fly.stderr.splitlines() if "cannot listen" in line]
    assert len(errors) == 1, fly.stderr
    assert errors[0].startswith("gcs fly: vehicle 3")
    assert f"udp 127.0.0.1:{base + 2} (link.local_port)" in errors[0]
