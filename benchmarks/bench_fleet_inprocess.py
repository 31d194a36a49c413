"""The emulator fleet's own cost, sockets aside: CPU seconds per simulated second, in-process.

    python benchmarks/bench_fleet_inprocess.py [ROOT ...]

100 vehicles of the default personality in the air (10 x 10 grid at 10 m), 2 ms ticks, the
links discarded (no sockets, no encoding cost beyond the telemetry bytes built), 0.5 s of warm-up
(numba compilation, caches) and then 10 s simulated; prints the CPU time as a percentage of one
core for each checkout ROOT given (default: this one), so two commits compare on the same
machine in one command (a git worktree per commit). docs/benchmarks.md quotes it.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

_CHILD = r'''
import sys, time
sys.path.insert(0, sys.argv[1])
from vehicle_emulator.runner import Emulator
from vehicle_emulator.team import parse_team

class Discard:
    name = "discard"
    def send(self, data, addr=None):
        pass

vehicles = [{"id": k + 1, "initial": {"position_enu_m": [3.0 * (k % 10), 3.0 * (k // 10), 10.0]}}
            for k in range(100)]
emu = Emulator(list(parse_team({"vehicles": vehicles}).vehicles))
for node in emu.nodes:
    node.links.append(Discard())
t = 0.0
for _ in range(250):
    t += 0.002
    emu.advance_to(t)
c0 = time.process_time()
for _ in range(5000):
    t += 0.002
    emu.advance_to(t)
print(f"{(time.process_time() - c0) / 10.0 * 100:.1f}")
'''


def main(argv: list[str]) -> int:
    roots = [Path(a).resolve() for a in argv] or [Path(__file__).resolve().parents[1]]
    for root in roots:
        out = subprocess.run([sys.executable, "-c", _CHILD, str(root)], capture_output=True,
                             text=True, check=True)
        print(f"{root}: {out.stdout.strip()} % of one core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
