"""The emulator fleet over real sockets, driven like `gcs fly` drives it: CPU and real time.

    python -m benchmarks.bench_fleet_sockets [--vehicles N] [--physics-rate HZ] [--tick-ms MS]
        [--autopilot px4] [--seconds S] [--streams default|requested] [--root DIR] [--json FILE]

One ``vehicle-emu --fleet`` process (checkout ``--root``, default this one) flies N vehicles
(a grid at 10 m, in the air) whose links all send to ONE ground-station port (team file
``link: {local_port: G, remote_port: B + i}``). This process plays the ground station, cheaply,
on the other core: it asks every vehicle for the streams `gcs fly` asks for
(MAV_CMD_SET_MESSAGE_INTERVAL, GCS_RATES_HZ; one stream at a time, the next after every
vehicle's ACK, as gcs fly awaits each), switches them to OFFBOARD and sends each one a
SET_ATTITUDE_TARGET (body rates and thrust, type_mask 128) every 10 ms, as rates mode at 100 Hz
does (one datagram per vehicle per tick, all from the one port), from a level-holding P law on
the telemetry it reads (every datagram; only ATTITUDE_QUATERNION and LOCAL_POSITION_NED decoded). Over the
measurement window (after the set-up) it reads the emulator's CPU time from /proc; the
emulator's own ``--stats-json`` gives simulated and wall time, dropped simulated time and its
tick lateness. Prints one JSON line; docs/benchmarks.md ("Emulator fleet at 1 kHz") quotes it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import select
import socket
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from pymavlink.dialects.v20 import common as mavlink

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.bench_fleet_inprocess import GCS_RATES_HZ  # noqa: E402
from benchmarks.fleet import fleet  # noqa: E402
from vehicle_emulator.mavlink.codec import BatchEncoder  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GCS_PORT = 24550
BIND_BASE = 24700
SETPOINT_PERIOD_S = 0.01
LEVEL_GAIN = 2.0  # rad/s per unit tilt (the GCS stand-in's level-holding P law)
_QUAT = struct.Struct("<4f")
_FLOAT = struct.Struct("<f")
CLK_TCK = os.sysconf("SC_CLK_TCK")


def team_file(n: int, autopilot: str, path: Path) -> None:
    """n vehicles on a grid 3 m apart at 10 m, one shared GCS port."""
    cols = max(1, int(round(math.sqrt(n))))
    vehicles = [
        {"id": k + 1,
         "initial": {"position_enu_m": [3.0 * (k % cols), 3.0 * (k // cols), 10.0]},
         "link": {"local_port": GCS_PORT, "remote_host": "127.0.0.1",
                  "remote_port": BIND_BASE + k}}
        for k in range(n)
    ]
    path.write_text(yaml.safe_dump({"name": f"bench{n}", "emulator": {"autopilot": autopilot},
                                    "vehicles": vehicles}))


def cpu_s(pid: int) -> tuple[float, float]:
    """(user, system) CPU seconds of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) / CLK_TCK, int(fields[12]) / CLK_TCK


class Gcs:
    """The cheap ground station: one UDP socket, pre-framed setpoints."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.bind(("127.0.0.1", GCS_PORT))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.addr = [("127.0.0.1", BIND_BASE + k) for k in range(n)]
        self.acks: dict[tuple[int, int], int] = {}
        self.interval_acks: dict[int, int] = {}  # sysid -> SET_MESSAGE_INTERVAL ACKs so far
        self.hover = 0.5
        self.datagrams = 0
        self.bytes = 0
        self.heard: set[int] = set()
        self.q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.vz = np.zeros(n)
        self.encoder = BatchEncoder(mavlink.MAVLink_set_attitude_target_message, compid=190)
        self.rows_vehicle = np.arange(n)
        self.sysid = np.full(n, 255, dtype=np.uint8)
        self.seq = np.zeros(n, dtype=np.uint8)

    def frame(self, msg) -> bytes:
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        return data

    def command(self, k: int, cmd: int, *p: float) -> None:
        p = list(p) + [0.0] * (7 - len(p))
        self.sock.sendto(self.frame(mavlink.MAVLink_command_long_message(k + 1, 1, cmd, 0, *p)),
                         self.addr[k])

    def setpoints(self) -> list[bytes]:
        """This tick's SET_ATTITUDE_TARGET per vehicle: body rates from a level-holding P law
        on the vehicle's last ATTITUDE_QUATERNION (rates mode: zero rates alone would let the
        vehicles drift on their gyro bias and fall), hover thrust damped by LOCAL_POSITION_NED
        vz; framed in one batch (the emulator's own BatchEncoder)."""
        w, x, y, z = self.q.T
        down_x = 2.0 * (x * z - w * y)  # NED down in FRD body axes: the third row of R
        down_y = 2.0 * (y * z + w * x)
        down_z = np.maximum(1.0 - 2.0 * (x * x + y * y), 0.5)
        rows = self.encoder.empty(self.n)
        rows["target_system"] = np.arange(1, self.n + 1)
        rows["target_component"] = 1
        rows["type_mask"] = 128  # attitude ignored: body rates + thrust
        rows["q"] = (1.0, 0.0, 0.0, 0.0)
        rows["body_roll_rate"] = -LEVEL_GAIN * down_y
        rows["body_pitch_rate"] = LEVEL_GAIN * down_x
        rows["thrust"] = np.clip(self.hover * (1.0 + 0.3 * self.vz) / down_z, 0.0, 1.0)
        out, ln = self.encoder.encode(rows, self.rows_vehicle, self.sysid, self.seq)
        return [out[k, : ln[k]].tobytes() for k in range(self.n)]

    def drain(self, parse: bool) -> None:
        """What has arrived, up to 1000 datagrams (parsing everything is slower than a large
        fleet sends: an unbounded drain would stall the setpoints)."""
        sock, q, vz = self.sock, self.q, self.vz
        for _ in range(1000):
            try:
                data, addr = sock.recvfrom(4096)
            except BlockingIOError:
                return
            self.datagrams += 1
            self.bytes += len(data)
            k = addr[1] - BIND_BASE
            self.heard.add(k)
            pos, end = 0, len(data)
            while pos + 12 <= end and data[pos] == 0xFD:  # the two messages the law reads
                plen = data[pos + 1]
                mid = data[pos + 7] | data[pos + 8] << 8 | data[pos + 9] << 16
                if mid == 31 or mid == 32:
                    payload = data[pos + 10 : pos + 10 + plen] + bytes(28)
                    if mid == 31:
                        q[k] = _QUAT.unpack_from(payload, 4)
                    else:
                        vz[k] = _FLOAT.unpack_from(payload, 24)[0]
                pos += 12 + plen
            if parse:
                for m in self.parser.parse_buffer(data) or []:
                    t = m.get_type()
                    if t == "COMMAND_ACK":
                        key = (m.get_srcSystem(), m.command)
                        self.acks[key] = m.result
                        if m.command == 511:
                            sysid = m.get_srcSystem()
                            self.interval_acks[sysid] = self.interval_acks.get(sysid, 0) + 1
                    elif t == "PARAM_VALUE" and m.param_id.startswith("MPC_THR_HOVER"):
                        self.hover = m.param_value

    def wait(self, until: float, parse: bool) -> None:
        while True:
            left = until - time.monotonic()
            if left <= 0:
                return
            select.select([self.sock], [], [], left)
            self.drain(parse)

    def stream(self, seconds: float, parse: bool) -> int:
        """Setpoints every SETPOINT_PERIOD_S for ``seconds``; returns late ticks (> 1 period)."""
        t = time.monotonic()
        end = t + seconds
        late = 0
        while t < end:
            frames = self.setpoints()
            for k in range(self.n):
                self.sock.sendto(frames[k], self.addr[k])
            t += SETPOINT_PERIOD_S
            if time.monotonic() > t:
                late += 1
                t = time.monotonic()
            self.wait(t, parse)
        return late


def run(args: argparse.Namespace) -> dict:
    n = args.vehicles
    root = Path(args.root).resolve()
    with tempfile.TemporaryDirectory() as tmp:
        team = Path(tmp) / "team.yaml"
        stats = Path(tmp) / "stats.json"
        team_file(n, args.autopilot, team)
        gcs = Gcs(n)  # bound before the fleet starts sending
        prof = ["-m", "cProfile", "-o", args.profile] if args.profile else []
        options = ["--physics-rate", str(args.physics_rate), "--tick-ms", str(args.tick_ms),
                   "--stats-json", str(stats)]
        if args.streams != "default":
            options += ["--streams", args.streams]
        # the checkout `root`'s fleet (run from it), its stderr on this one's
        with fleet(team, *options, cwd=root, python=[sys.executable, *prof], log=None) as emu:
            # set-up, parsing everything: hover thrust, streams, OFFBOARD
            gcs.sock.sendto(gcs.frame(mavlink.MAVLink_param_request_read_message(
                1, 1, b"MPC_THR_HOVER", -1)), gcs.addr[0])
            # one stream at a time, each round after every vehicle's ACK, as gcs fly's
            # CONFIGURE awaits each set_message_interval (the commands reach a vehicle in
            # different ticks)
            for r, (mid, hz) in enumerate(GCS_RATES_HZ.items()):
                for _attempt in range(3):
                    for k in range(n):
                        if gcs.interval_acks.get(k + 1, 0) <= r:
                            gcs.command(k, 511, mid, 1e6 / hz if hz > 0 else -1.0)
                    deadline = time.monotonic() + 1.0
                    while (time.monotonic() < deadline
                           and min(gcs.interval_acks.get(k + 1, 0) for k in range(n)) <= r):
                        gcs.wait(time.monotonic() + 0.002, parse=True)
                    if min(gcs.interval_acks.get(k + 1, 0) for k in range(n)) > r:
                        break
            gcs.stream(1.0, parse=True)
            for k in range(n):
                gcs.command(k, 176, 1 + 128, 6)
            gcs.stream(1.0, parse=True)
            offboard = sum(1 for k in range(n) if gcs.acks.get((k + 1, 176)) == 0)
            # the measurement
            gcs.datagrams = gcs.bytes = 0
            gcs.heard.clear()
            u0, s0 = cpu_s(emu.pid)
            w0 = time.monotonic()
            late = gcs.stream(args.seconds, parse=False)
            wall = time.monotonic() - w0
            u1, s1 = cpu_s(emu.pid)
        st = json.loads(stats.read_text())  # written when the fleet stopped
    modes: dict[str, int] = {}
    for v in st["by_vehicle"]:
        key = f"{v['mode']}{' armed' if v['armed'] else ''}"
        modes[key] = modes.get(key, 0) + 1
    return {
        "vehicles": n, "physics_rate_hz": args.physics_rate, "tick_ms": args.tick_ms,
        "autopilot": args.autopilot, "streams": args.streams, "window_s": round(wall, 2),
        "cpu_percent": round(100.0 * (u1 - u0 + s1 - s0) / wall, 1),
        "user_percent": round(100.0 * (u1 - u0) / wall, 1),
        "sys_percent": round(100.0 * (s1 - s0) / wall, 1),
        "realtime_factor": round(st["sim_s"] / st["wall_s"], 4),
        "dropped_sim_s": round(st["dropped_sim_s"], 3),
        "late_mean_ms": round(st["late_mean_ms"], 2), "late_p99_ms": round(st["late_p99_ms"], 2),
        "datagrams_in_per_s": round(gcs.datagrams / wall), "bytes_in_per_s": round(gcs.bytes / wall),
        "vehicles_heard": len(gcs.heard), "offboard_acked": offboard,
        "gcs_late_ticks": late, "modes_at_end": modes,
        "telemetry_by_type_per_s": {k: round(v / st["sim_s"]) for k, v in
                                    st["telemetry_by_type"].items() if v},
    }


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vehicles", type=int, default=240)
    ap.add_argument("--physics-rate", type=float, default=1000.0)
    ap.add_argument("--tick-ms", type=float, default=2.0)
    ap.add_argument("--autopilot", default="px4")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--streams", default="requested", choices=("default", "requested"))
    ap.add_argument("--root", default=str(ROOT))
    ap.add_argument("--profile", help="run the fleet under cProfile, writing this file")
    ap.add_argument("--json", help="append the result to this file (one JSON a line)")
    args = ap.parse_args(argv)
    result = run(args)
    print(json.dumps(result))
    if args.json:
        with open(args.json, "a") as fh:
            fh.write(json.dumps(result) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
