"""The emulator fleet's own cost, sockets aside: CPU seconds per simulated second, in-process.

    python -m benchmarks.bench_fleet_inprocess [ROOT ...] [--vehicles N] [--physics-rate HZ]
        [--tick-ms MS] [--autopilot px4|ardupilot|nominal] [--seconds S] [--gcs-streams]
        [--streams default|requested]

N vehicles (default 100) of a personality (default px4) in the air (a grid 3 m apart at 10 m),
physics at ``--physics-rate`` (1000 Hz), ``--tick-ms`` ticks (2), the links discarded (no
sockets, no encoding cost beyond the telemetry bytes built), 0.5 s of warm-up (numba
compilation, caches) and then ``--seconds`` (10) simulated; prints the CPU time as a percentage
of one core and the real-time factor the loop could reach (simulated s per CPU s) for each
checkout ROOT given (default: this one), so two commits compare on the same machine in one
command (a checkout per commit, e.g. ``git archive COMMIT | tar -x -C DIR``). ``--gcs-streams``
sets every vehicle's streams to the ones `gcs fly` asks for (bench_fleet_sockets.GCS_RATES_HZ),
through the same ``Telemetry.set_interval`` a MAV_CMD_SET_MESSAGE_INTERVAL reaches.
docs/benchmarks.md quotes it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

# what gcs fly asks each vehicle for (gcs/fly/setup.py, gcs/fly/commander.py; msgid: Hz; 0: off);
# bench_fleet_sockets.py sends these
GCS_RATES_HZ = {31: 100.0, 32: 100.0, 105: 100.0, 245: 5.0, 83: 10.0, 33: 5.0, 30: 0.0, 331: 0.0}

# run by `python -c` with the checkout as its working directory: `-c` puts the working
# directory first on the import path, so the child imports that checkout's packages
_CHILD = r'''
import json, sys, time
cfg = json.loads(sys.argv[1])
from flightkit import jitcache
jitcache.configure()
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.config.team import parse_team

class Discard:
    name = "discard"
    def send(self, data, addr=None):
        pass

n = cfg["vehicles"]
cols = max(1, int(round(n ** 0.5)))
vehicles = [{"id": k + 1, "initial": {"position_enu_m": [3.0 * (k % cols), 3.0 * (k // cols), 10.0]},
             "emulator": {"autopilot": cfg["autopilot"]}} for k in range(n)]
kw = {"streams": cfg["stream_mode"]} if cfg["stream_mode"] != "default" else {}
emu = Emulator(list(parse_team({"vehicles": vehicles}).vehicles),
               physics_rate_hz=cfg["physics_rate_hz"], tick_s=cfg["tick_s"], **kw)
for node in emu.nodes:
    node.links.append(Discard())
    for msgid, hz in cfg["streams"].items():
        emu.telemetry.set_interval(node.index, int(msgid), 1e6 / hz if hz > 0 else -1.0, 0.0)
t = 0.0
dt = cfg["tick_s"]
for _ in range(int(round(0.5 / dt))):
    t += dt
    emu.advance_to(t)
ticks = int(round(cfg["seconds"] / dt))
steps0, c0 = emu.plant.steps_done, time.process_time()
for _ in range(ticks):
    t += dt
    emu.advance_to(t)
cpu = time.process_time() - c0
sim = (emu.plant.steps_done - steps0) * emu.plant.dt_s
print(json.dumps({"cpu_percent": 100.0 * cpu / sim, "sim_s": sim, "cpu_s": cpu,
                  "physics_steps_per_s": (emu.plant.steps_done - steps0) / sim,
                  "msgs_per_s": int(emu.telemetry.sent.sum()) / (sim + 0.5)}))
'''


def measure(root: Path, vehicles: int, physics_rate_hz: float, tick_ms: float, autopilot: str,
            seconds: float, gcs_streams: bool, stream_mode: str = "default") -> dict[str, float]:
    """One run in a fresh interpreter on checkout ``root``: the child's figures."""
    cfg = {"vehicles": vehicles, "physics_rate_hz": physics_rate_hz, "tick_s": tick_ms * 1e-3,
           "autopilot": autopilot, "seconds": seconds,
           "streams": GCS_RATES_HZ if gcs_streams else {}, "stream_mode": stream_mode}
    out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(cfg)], cwd=root,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("roots", nargs="*", type=Path)
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--physics-rate", type=float, default=1000.0)
    ap.add_argument("--tick-ms", type=float, default=2.0)
    ap.add_argument("--autopilot", default="px4")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--gcs-streams", action="store_true")
    ap.add_argument("--streams", default="default", choices=("default", "requested"),
                    help="vehicle-emu --streams (requested: needs a checkout that has it)")
    args = ap.parse_args(argv)
    roots = [r.resolve() for r in args.roots] or [Path(__file__).resolve().parents[1]]
    for root in roots:
        r = measure(root, args.vehicles, args.physics_rate, args.tick_ms, args.autopilot,
                    args.seconds, args.gcs_streams, args.streams)
        print(f"{root}: {r['cpu_percent']:.1f} % of one core ({args.vehicles} vehicles, "
              f"{r['physics_steps_per_s']:.0f} physics steps/s simulated, "
              f"{r['msgs_per_s']:.0f} msg/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
