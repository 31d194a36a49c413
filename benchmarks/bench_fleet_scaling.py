"""The emulator fleet from 16 to 240 vehicles at 1 kHz physics, before and after: docs section.

    python -m benchmarks.bench_fleet_scaling [--before DIR] [--sizes 16,64,144,240]
        [--seconds S] [--no-doc]

For each fleet size: ``bench_fleet_inprocess.py`` (no sockets; the streams `gcs fly` asks for)
and ``bench_fleet_sockets.py`` (one fleet process driven like `gcs fly` rates mode at 100 Hz over
one shared GCS port), on this checkout (``--streams requested``) and, with ``--before``, on an
older checkout (e.g. ``git archive ab87930 | tar -x -C /tmp/before``; its default streams, the
same SET_MESSAGE_INTERVAL requests). Writes the "Emulator fleet at 1 kHz" section of
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

from benchmarks import bench_fleet_inprocess as inproc
from benchmarks import bench_fleet_sockets as sockets
from benchmarks.docsection import write_section

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## Emulator fleet at 1 kHz"
ANALYSIS = """
Where the time goes at 240 vehicles (cProfile of the fleet under this load, and
`bench_fleet_inprocess.py`): not in the physics. The plant, the onboard models and PX4's rate
loop for the whole fleet are one numba call per tick (two 1 ms RK4 steps: about 8 % of a
core); the 50 Hz autopilot logic is Python per vehicle (about 6 %; the tick gathers every
vehicle's observation from the fleet's arrays at once and writes the status and battery by
column: 3.9 us a vehicle, against 7.7 us for each node's own `observe` and `refresh_status`,
which `tests/unit/test_emulator_runner.py` checks give the same values); telemetry is built
and framed in batches (about 3 %). The input costs the most: 24,000 SET_ATTITUDE_TARGETs a
second. The sockets are read in bulk (`server.LinkPoller`: one epoll reader for all of them,
at most 8 datagrams a socket and 512 a wake-up, so a backlog is worked off between ticks
instead of holding the physics up), the hot frames are checked in one numba call
(`codec.HotDecoder`: about 1.5 us a message against pymavlink's 8-10 us), and sends go
straight to the socket. `--streams requested` (no SYS_STATUS, TIMESYNC requests,
BATTERY_STATUS or HOME_POSITION; ATTITUDE, ODOMETRY and the 50 Hz GLOBAL_POSITION_INT only
until the ground station turns them off) removes 5 % of the messages and little CPU: they
mostly ride in datagrams that leave anyway. The three 100 Hz messages the ground station asks
for leave in one datagram per vehicle per 10 ms.

What is left is per datagram and cannot be batched in Python: one `recvfrom` per setpoint and
one `sendto` per telemetry datagram (48,000 socket calls a second at 240 vehicles, 8-12 % of a
core in the kernel alone), as every vehicle has its own socket (its own port, as PX4 SITL
instances do) and Python has neither `recvmmsg` nor `sendmmsg`; and about 4 us of Python per
setpoint in the vehicle's handler (target and echo checks, PX4's type_mask rules, offboard
bookkeeping). Below about 40 % of a core at 240 vehicles needs fewer datagrams (all vehicles
behind one emulator socket, several vehicles' messages per datagram, the ground station
telling them apart by sysid only) or the setpoint handling and socket calls in a compiled
extension. At small fleets the fixed cost of the 500 Hz tick loop and its wake-ups dominates
(an idle 16-vehicle fleet: 7 % of a core).
"""


def measure(root: Path, n: int, seconds: float, requested: bool) -> dict:
    """In-process and socket figures of one checkout at one fleet size."""
    streams = "requested" if requested else "default"
    ip = inproc.measure(root, n, 1000.0, 2.0, "px4", seconds, True, streams)
    args = argparse.Namespace(vehicles=n, physics_rate=1000.0, tick_ms=2.0, autopilot="px4",
                              seconds=seconds, streams=streams, root=str(root), profile=None)
    so = sockets.run(args)
    return {"inproc": ip, "sockets": so}


def row(label: str, n: int, r: dict) -> str:
    ip, so = r["inproc"], r["sockets"]
    modes = ", ".join(f"{v} {k}" for k, v in so["modes_at_end"].items())
    return (f"| {n} | {label} | {ip['cpu_percent']:.1f} % | {100.0 / ip['cpu_percent']:.1f} | "
            f"**{so['cpu_percent']:.1f} %** ({so['user_percent']:.1f} + {so['sys_percent']:.1f}) | "
            f"{so['realtime_factor']:.4f} | {so['dropped_sim_s']:.2f} s | "
            f"{so['late_mean_ms']:.2f} / {so['late_p99_ms']:.2f} ms | "
            f"{so['datagrams_in_per_s']:,} | {modes} |")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", type=Path, help="checkout of the commit to compare against")
    ap.add_argument("--before-label", default="before")
    ap.add_argument("--sizes", default="16,64,144,240")
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--no-doc", action="store_true")
    ap.add_argument("--rows", type=Path,
                    help="write the section from the table rows of an earlier run's output")
    ap.add_argument("--note", default="", help="a paragraph after the table (how it was run)")
    args = ap.parse_args(argv)
    sizes = [] if args.rows else [int(x) for x in args.sizes.split(",")]
    rows = []
    if args.rows:
        seen = set()
        for line in args.rows.read_text().splitlines():
            if line.startswith("| ") and line[2].isdigit() and line not in seen:
                seen.add(line)
                rows.append(line)
    for n in sizes:
        if args.before is not None:
            r = measure(args.before.resolve(), n, args.seconds, requested=False)
            rows.append(row(args.before_label, n, r))
            print(rows[-1], flush=True)
        r = measure(ROOT, n, args.seconds, requested=True)
        rows.append(row("after", n, r))
        print(rows[-1], flush=True)
    load = os.getloadavg()
    load_text = "" if args.rows else f" (load average {load[0]:.1f} at the end)"
    text = f"""{HEADING}

`python -m benchmarks.bench_fleet_scaling --before DIR` on {platform.machine()}, {os.cpu_count()} CPU(s), Python {platform.python_version()}: px4 personality, physics at 1 kHz (`sim.plant_rate_hz` 1000: one RK4 step per millisecond, stepped in whole steps to the clock every 2 ms tick), vehicles in the air on a grid, {args.seconds:g} s measured per run. **No sockets**: `bench_fleet_inprocess.py --gcs-streams` (simulation, autopilots, telemetry building; links discarded), CPU per simulated second and the real-time factor that CPU alone would allow. **Sockets**: `bench_fleet_sockets.py`: one `vehicle-emu --fleet` process whose vehicles all send to ONE ground-station port, driven by a stand-in for `gcs fly --mode rates` in another process (MAV_CMD_SET_MESSAGE_INTERVAL for what gcs fly asks (gcs/fly/setup.py): ATTITUDE_QUATERNION, LOCAL_POSITION_NED, HIGHRES_IMU 100 Hz, ATTITUDE_TARGET 10, EXTENDED_SYS_STATE, GLOBAL_POSITION_INT, HEARTBEAT 5, ATTITUDE and ODOMETRY off; OFFBOARD; a SET_ATTITUDE_TARGET with body rates and thrust to every vehicle every 10 ms); the fleet's CPU over the window from /proc (user + system), its real-time factor (simulated / wall seconds over its whole run), simulated time dropped, its tick lateness, the datagrams/s the ground station received, and the vehicles' mode at the end. "{args.before_label}": the checkout before this work with its default streams; "after": this one with `--streams requested`. The machine was shared with other engineers' jobs, which moves the socket figures by several points{load_text}.

| vehicles | version | no sockets: CPU of one core | no sockets: max real-time factor | sockets: CPU of one core (user + sys) | sockets: real-time factor | dropped | tick lateness mean / p99 | datagrams/s to the GCS | at the end |
|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(rows) + "\n" + (f"\n{args.note}\n" if args.note else "") + ANALYSIS
    if not args.no_doc:
        write_section(ROOT / "docs" / "benchmarks.md", HEADING, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
