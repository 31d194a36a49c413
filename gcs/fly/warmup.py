"""`gcs compile`'s part for `gcs fly`: the law compiled through the path a flight runs (its
warm-up in `Flight`), so that no flight compiles while a link timeout or a vehicle waits."""

from __future__ import annotations

import tempfile
from pathlib import Path

from flightkit.jitcache import compiling, is_compiled
from gcs.config.compile_team import VARIANTS, compile_team
from gcs.fly.flight import Flight
from gcs.fly.setup import FlyOptions, prepare

#: First-run compile time of the law on a quiet 2-core machine (docs/benchmarks.md,
#: "Start-up"), for the notice: measured 17.6-29.7 s (2026-12-04).
LAW_COMPILE_S = 25.0


def compile_law(prog: str = "gcs", force: bool = True) -> None:
    """Compile the law as `gcs fly` runs it (its warm-up in `Flight`), every law and method;
    with force=False, only when the cache does not hold it yet."""
    if not force and is_compiled("law"):
        return
    with (compiling("law", "the control law", LAW_COMPILE_S, prog),
          tempfile.TemporaryDirectory() as tmp):
        options = FlyOptions(out_dir=Path(tmp))  # the law is the same in every mode
        for law, derivative in VARIANTS:
            Flight(prepare(compile_team(law, derivative), options), options)
