"""Keeps numba's on-disk cache consistent with the sources: one cache directory per source state.

numba's `cache=True` re-checks only the file of the function it compiled, not the files of the
compiled functions it calls, so after an edit or an upgrade a caller could run stale machine
code of a callee. Keying the cache directory by a digest of every source file of this
distribution (flightkit, gcs and vehicle_emulator) rules that out. A user's NUMBA_CACHE_DIR is
respected.

numba picks a function's cache directory when `@njit(cache=True)` decorates it, that is when its
module is imported. So `configure()` is the first thing each program does, before it imports any
compiled module: the entry points (`gcs.cli.main`, `vehicle_emulator.fleet.cli.main`), the test
suite's conftest.py and the benchmark scripts call it; importing a package never does. Code that
imports compiled modules without it runs correctly, but caches in numba's default places.

Compiling takes seconds (docs/benchmarks.md), so a program never does it silently:
`compiling(part, estimate_s)` wraps the warm-up of one part (the law, the simulator, the
emulator physics). When that part has not been compiled into the current cache yet, it prints
what is compiling and why, and how long it took; afterwards it leaves a marker file so later runs
stay quiet. `gcs compile` (run by `make install`) fills the cache ahead of any flight.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

_PACKAGES = ("flightkit", "gcs", "vehicle_emulator")
_KEEP = 3  # cache directories of other source states kept, newest first
_digest = ""  # of the sources this process runs (set by configure)


def source_digest(root: Path) -> str:
    """SHA-1 over the paths and contents of the .py files of the packages that use numba."""
    digest = hashlib.sha1()
    for package in _PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            content = path.read_bytes()
            if b"numba" in content and path.name != "jitcache.py":
                digest.update(str(path.relative_to(root)).encode())
                digest.update(content)
    return digest.hexdigest()[:16]


def configure() -> None:
    """Point NUMBA_CACHE_DIR at the cache of the current sources and delete all but the `_KEEP`
    newest caches of other source states. Call it before importing any module with a
    `cache=True` function: one imported earlier keeps the cache directory numba found then."""
    global _digest
    root = Path(__file__).resolve().parent.parent
    _digest = source_digest(root)
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    base = (
        Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "formation-gcs" / "numba"
    )
    target = base / _digest
    try:
        target.mkdir(parents=True, exist_ok=True)
        others = sorted(
            (p for p in base.iterdir() if p.is_dir() and p != target),
            key=lambda p: p.stat().st_mtime,
            reverse=True,
        )
        for stale in others[_KEEP:]:
            shutil.rmtree(stale, ignore_errors=True)
    except OSError:
        return  # read-only home: numba falls back to its own default locations
    os.environ["NUMBA_CACHE_DIR"] = str(target)
    if "numba" in sys.modules:
        from numba.core import config

        config.reload_config()


def _marker(part: str) -> Path | None:
    cache = os.environ.get("NUMBA_CACHE_DIR")
    # the digest is in the name too, for a user's own NUMBA_CACHE_DIR that outlives edits
    return Path(cache) / f"{part}-{_digest}.compiled" if cache else None


def is_compiled(part: str) -> bool:
    """True when `part` was compiled into the current cache (its marker exists)."""
    marker = _marker(part)
    return marker is not None and marker.exists()


@contextlib.contextmanager
def compiling(part: str, what: str, estimate_s: float, prog: str,
              stream: TextIO | None = None) -> Iterator[None]:
    """Announce a first-run compile of `part` (`what` in words) on `stream` (stderr), time it,
    and mark the part compiled when the block succeeds. Silent when the cache is warm."""
    out = stream if stream is not None else sys.stderr
    announce = not is_compiled(part)
    t0 = time.monotonic()
    if announce:
        print(f"{prog}: compiling {what} (first run after an install or an edit only, "
              f"about {estimate_s:.0f} s on 2 idle cores, longer on a busy machine) ...", file=out,
              flush=True)
    yield
    if not announce:
        return
    print(f"{prog}: compiled {what} in {time.monotonic() - t0:.1f} s", file=out, flush=True)
    marker = _marker(part)
    if marker is not None:
        with contextlib.suppress(OSError):
            marker.touch()
