"""The line an emulator fleet prints on stdout once every link is open, and how a parent reads
it: ``vehicle-emu: ready: 4 vehicles (sysid 1, 2, 3, 4) personalities 1:px4 2:px4 3:px4
4:px4`` (vehicle id:personality), optionally followed by ``; ...`` notes. Pure."""

from __future__ import annotations

import re
from collections.abc import Sequence

READY_PREFIX = "vehicle-emu: ready:"
_PERSONALITIES = re.compile(r" personalities ((?:\d+:[A-Za-z0-9_-]+ ?)+)")


def ready_line(sysids: Sequence[int], personalities: Sequence[tuple[int, str]],
               notes: str = "") -> str:
    """The ready line of a fleet of ``sysids`` whose vehicles (id, personality name) are
    ``personalities``; ``notes`` (if any) follow after "; "."""
    n = len(sysids)
    kinds = " ".join(f"{vehicle_id}:{name}" for vehicle_id, name in personalities)
    return (f"{READY_PREFIX} {n} vehicle{'s' if n != 1 else ''} "
            f"(sysid {', '.join(str(s) for s in sysids)}) personalities {kinds}"
            + (f"; {notes}" if notes else ""))


def ready_personalities(line: str) -> dict[int, str]:
    """Per vehicle id, its personality name, from a ready line (empty if it names none)."""
    m = _PERSONALITIES.search(line)
    if m is None:
        return {}
    pairs = (item.split(":", 1) for item in m.group(1).split())
    return {int(vehicle_id): name for vehicle_id, name in pairs}
