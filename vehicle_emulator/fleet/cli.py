"""``vehicle-emu``'s entry point: points numba's cache at the current sources, then runs the
command line (command.py, which imports the compiled physics; docs/emulator.md)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from flightkit import jitcache

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vehicle-emu`` console script; returns its exit status."""
    jitcache.configure()  # before the import below: numba fixes a kernel's cache when it decorates
    from vehicle_emulator.fleet.command import main as run

    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
