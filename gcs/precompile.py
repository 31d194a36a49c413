"""`gcs compile`: fill numba's on-disk cache before any flight (run by `make install`).

The law, the in-process simulator and the emulator physics are numba-compiled. A cold cache
costs about 20-30 s (law), 27 s (simulator alone; 10-15 s after the law) and 35-45 s (emulator
physics, every personality) on a quiet 2-core machine, and several times that on a busy one
(docs/benchmarks.md, "Start-up"). Compiling them here, once per source state, means neither
`gcs fly` nor `vehicle-emu` nor `gcs sim` has to do it while a user, a link timeout or a vehicle
waits. Each part is compiled through exactly the code path the programs run (a `Flight` of a
small built-in team, a short `simulate`, `vehicle-emu --compile-only`), so what is cached is what
they load. The emulator compiles in its own process, beside this one: it is an independent peer,
and the two cores finish sooner that way.
"""

from __future__ import annotations

import subprocess
import sys
import time

from gcs.fly.warmup import compile_law
from gcs.sim.warmup import compile_sim
from gcs.sweep.measure import compile_measure


def _font_cache() -> None:
    """matplotlib builds its font list on first import in a new home: do it now too."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.font_manager  # noqa: F401


def compile_all(emulator: bool = True) -> None:
    """Compile every part into the cache and say so on stderr. Raises RuntimeError if the
    emulator's compile failed."""
    t0 = time.monotonic()
    proc = None
    if emulator:
        proc = subprocess.Popen([sys.executable, "-m", "vehicle_emulator", "--compile-only"],
                                stdin=subprocess.DEVNULL)
    try:
        compile_law()
        compile_sim()
        compile_measure()  # gcs sweep's measure of each run
        _font_cache()
    finally:
        code = proc.wait() if proc is not None else 0
    if code != 0:
        raise RuntimeError(f"vehicle-emu --compile-only failed with exit status {code}")
    wall = time.monotonic() - t0
    parts = "the law, the simulator" + (" and the emulator physics" if emulator else "")
    print(f"gcs compile: {parts} are compiled and cached ({wall:.1f} s)", file=sys.stderr,
          flush=True)


__all__ = ["compile_all", "compile_law", "compile_sim"]
