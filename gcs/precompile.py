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
import tempfile
import time
from pathlib import Path

from flightkit.jitcache import compiling, is_compiled

#: First-run compile times on a quiet 2-core machine (docs/benchmarks.md, "Start-up"), for the
#: notice: measured 17.6-29.7 s law, 7.8-14.7 s simulator after it, 27 s simulator alone
#: (2026-12-04).
LAW_COMPILE_S = 25.0
SIM_COMPILE_S = 27.0  # alone
SIM_AFTER_LAW_S = 12.0  # when the law's kernels are cached already

# Two vehicles are enough: numba specialises on array types, not sizes. Both laws and both
# derivative methods are compiled (placeholders filled in by `_team`).
_TEAM_YAML = """\
name: compile
mission: {{duration_s: 1.0}}
controller:
  law: {law}
  mode: rates
  gains: {{c_p: 4.0, alpha_p: 2.0, alpha_m: 1.0, sigma_a: 1.0, alpha_eps: 32.0,
          alpha_omega: 32.0, c_eps: 0.5, alpha_rho: 0.5, k_eps: 8.0}}
  derivative: {{method: {derivative}}}
reference_velocity:
  x: {{constant: 0.0, cosines: [{{amplitude: 0.3, period_s: 23.0}}]}}
  y: {{constant: 0.0}}
  z: {{constant: 0.2}}
graph: {{edges: [[1, 2]]}}
fly: {{actuators: {{tick_rate_hz: 250, alpha_eps: 2.0, alpha_omega: 2.0, alpha_rho: 0.03}}}}
vehicles:
  - id: 1
    sysid: 1
    offset_enu_m: [1.0, 0.0, 0.0]
    initial: {{position_enu_m: [1.0, 0.0, 10.0]}}
    estimates: {{mhat: 1.0, inertia_kgm2: [0.08, 0.08, 0.08]}}
    nominal_mass_kg: 0.85
    airframe: {{arm_length_m: 0.2, anti_torque_m: 0.016, rotor_thrust_max_n: 6.0}}
    plant: {{mass_kg: 0.85, inertia_kgm2: [0.04856, 0.04856, 0.08801]}}
  - id: 2
    sysid: 2
    offset_enu_m: [-1.0, 0.0, 0.0]
    initial: {{position_enu_m: [-1.0, 0.0, 10.0]}}
    estimates: {{mhat: 4.0, inertia_kgm2: [0.08, 0.08, 0.08]}}
    nominal_mass_kg: 1.2
    airframe: {{arm_length_m: 0.25, anti_torque_m: 0.016, rotor_thrust_max_n: 8.0}}
    plant: {{mass_kg: 1.2, inertia_kgm2: [0.1522, 0.1522, 0.3]}}
"""

_VARIANTS = [(law, derivative) for law in ("adaptive", "baseline")
             for derivative in ("model", "levant")]


def _team(law: str, derivative: str):  # -> TeamConfig
    from gcs.config import team_from_yaml

    return team_from_yaml(_TEAM_YAML.format(law=law, derivative=derivative), "<gcs compile>")


def compile_law(prog: str = "gcs", force: bool = True) -> None:
    """Compile the law as `gcs fly` runs it (its warm-up in `Flight`), every law and method;
    with force=False, only when the cache does not hold it yet."""
    from gcs.fly.flight import Flight
    from gcs.fly.setup import FlyOptions, prepare

    if not force and is_compiled("law"):
        return
    with (compiling("law", "the control law", LAW_COMPILE_S, prog),
          tempfile.TemporaryDirectory() as tmp):
        options = FlyOptions(out_dir=Path(tmp))  # the law is the same in every mode
        for law, derivative in _VARIANTS:
            Flight(prepare(_team(law, derivative), options), options)


def compile_sim(prog: str = "gcs", force: bool = True) -> None:
    """Compile the in-process closed loop of `gcs sim` (both modes, laws and methods); with
    force=False, only when the cache does not hold it yet."""
    from gcs.config.modes import SIM_MODES
    from gcs.sim.runner import SimOptions, simulate

    if not force and is_compiled("sim"):
        return
    estimate = SIM_AFTER_LAW_S if is_compiled("law") else SIM_COMPILE_S
    with compiling("sim", "the simulator", estimate, prog):
        for law, derivative in _VARIANTS:
            for mode in SIM_MODES:
                simulate(_team(law, derivative), SimOptions(duration_s=0.01, mode=mode))


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
