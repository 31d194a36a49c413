"""Python's cyclic garbage collector, paced by the tick (docs/architecture.md, "The tick").

Left to itself the collector runs when allocations cross a threshold, which is wherever the
tick happens to be: inside a team's status check or the law's step. Its full collections walk
every object the process holds (the imported libraries, the compiled kernels, the flight log):
about 100 ms at 240 vehicles, ten ticks missed at 100 Hz, and young collections of a few ms push
the busiest ticks past their period. So, for the length of a flight:

* everything alive when the flight starts is moved to the permanent generation (`gc.freeze`),
  which no collection walks again;
* automatic collection is off; `after_tick` runs the collections the thresholds would have run,
  in the time between a tick's end and the next deadline, never inside a tick;
* while the tick streams setpoints (priming, the formation, the hand-over) no full collection
  runs: what survives the middle generation waits in the oldest one. Objects that become
  garbage are still freed at once by reference counting; only garbage *cycles* that old wait
  for the first full collection after the streaming phases;
* in the other phases (connecting, preflight, takeoff, go to start: the autopilots fly
  themselves) full collections run as Python's thresholds call for, over what the flight has
  allocated since it started;
* at the end the permanent generation is released and automatic collection restored.
"""

from __future__ import annotations

import gc
from typing import Self

#: Allocations (net) that trigger a youngest-generation collection: Python's own default.
YOUNG_THRESHOLD = 700
#: Youngest-generation collections per middle-generation one: Python's own default.
MIDDLE_EVERY = 10
#: Middle-generation collections per full one, outside the streaming phases: Python's default.
OLD_EVERY = 10
#: A collection is put off while less than this is left before the next deadline [s] ...
MIN_SLACK_S = 2e-3
#: ... but never past this many thresholds' worth of allocations (memory stays bounded).
MAX_DEFER = 20


class PacedCollector:
    """Collections in the tick's slack, none in a tick; a context for one flight."""

    def __init__(self) -> None:
        self._was_enabled = False
        self.young = 0  # collections run, by kind (what the tests read)
        self.middle = 0
        self.full = 0

    def __enter__(self) -> Self:
        self._was_enabled = gc.isenabled()
        gc.collect()  # before anything is timed: nothing to free later
        gc.freeze()
        gc.disable()
        return self

    def __exit__(self, *exc: object) -> None:
        gc.unfreeze()
        if self._was_enabled:
            gc.enable()

    def after_tick(self, slack_s: float, streaming: bool) -> None:
        """Run the collection the thresholds call for if ``slack_s`` (time to the next
        deadline) allows, or if it has been put off too long; ``streaming``: the tick sends
        setpoints (no full collection then)."""
        young, middle, old = gc.get_count()
        if young < YOUNG_THRESHOLD:
            return
        if slack_s < MIN_SLACK_S and young < MAX_DEFER * YOUNG_THRESHOLD:
            return
        if middle + 1 < MIDDLE_EVERY:
            gc.collect(0)
            self.young += 1
        elif streaming:
            gc.collect(1)
            self.middle += 1
        elif old + 1 >= OLD_EVERY:
            gc.collect(2)
            self.full += 1
        else:
            gc.collect(1)
            self.middle += 1
