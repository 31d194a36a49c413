"""`gcs compile`'s part for `gcs sim`: the in-process closed loop compiled through a short
`simulate` of every mode, law and derivative method."""

from __future__ import annotations

from flightkit.jitcache import compiling, is_compiled
from gcs.config.compile_team import VARIANTS, compile_team
from gcs.config.modes import SIM_MODES
from gcs.sim.runner import SimOptions, simulate

#: First-run compile times of the simulator on a quiet 2-core machine (docs/benchmarks.md,
#: "Start-up"), for the notice: measured 27 s alone, 7.8-14.7 s after the law (2026-12-04).
SIM_COMPILE_S = 27.0  # alone
SIM_AFTER_LAW_S = 12.0  # when the law's kernels are cached already


def compile_sim(prog: str = "gcs", force: bool = True) -> None:
    """Compile the in-process closed loop of `gcs sim` (both modes, laws and methods); with
    force=False, only when the cache does not hold it yet."""
    if not force and is_compiled("sim"):
        return
    estimate = SIM_AFTER_LAW_S if is_compiled("law") else SIM_COMPILE_S
    with compiling("sim", "the simulator", estimate, prog):
        for law, derivative in VARIANTS:
            for mode in SIM_MODES:
                simulate(compile_team(law, derivative), SimOptions(duration_s=0.01, mode=mode))
