"""Keeps numba's on-disk cache consistent with the sources: one cache directory per source state.

numba's `cache=True` re-checks only the file of the function it compiled, not the files of the
compiled functions it calls, so after an edit or an upgrade a caller could run stale machine
code of a callee. Keying the cache directory by a digest of every source file of this
distribution (gcs and vehicle_emulator) rules that out. A user's NUMBA_CACHE_DIR is respected.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

_PACKAGES = ("gcs", "vehicle_emulator")
_KEEP = 3  # cache directories of other source states kept, newest first


def source_digest(root: Path) -> str:
    """SHA-1 over the paths and contents of the .py files of both packages that use numba."""
    digest = hashlib.sha1()
    for package in _PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            content = path.read_bytes()
            if b"numba" in content and path.name != "jitcache.py":
                digest.update(str(path.relative_to(root)).encode())
                digest.update(content)
    return digest.hexdigest()[:16]


def configure() -> None:
    """Point NUMBA_CACHE_DIR at the cache of the current sources (call before compiling)."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    root = Path(__file__).resolve().parent.parent
    base = (
        Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "formation-gcs" / "numba"
    )
    target = base / source_digest(root)
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
