"""Announces numba compiles that begin after a program said ready.

A program warms up (compiles or loads from the cache) every kernel it will run before it prints
its ready line. A compile after that line blocks the program's only thread for seconds: its
links fall silent, and a peer that is waiting for an answer sees a vehicle that stopped talking.
`watch_late_compiles` makes that visible: each such compile is logged when it starts and ends and
recorded, so a run's statistics can say what the warm-up missed.
"""

from __future__ import annotations

import logging
import time

from numba.core import event as numba_event


class LateCompiles(numba_event.Listener):
    """Listener for numba's "numba:compile" events; `compiled` holds one
    "module.function(arg types)" per outermost compile (callees compiled for it are not listed).
    """

    def __init__(self, prog: str, logger: logging.Logger) -> None:
        self.prog = prog
        self.compiled: list[str] = []
        self._log = logger
        self._depth = 0
        self._t0 = 0.0

    def on_start(self, event: numba_event.Event) -> None:
        self._depth += 1
        if self._depth > 1:
            return
        self.compiled.append(_signature(event.data))
        self._t0 = time.monotonic()
        self._log.warning("%s: compiling %s after ready; this program sends nothing until it "
                          "is done (a specialisation its warm-up did not build)", self.prog,
                          self.compiled[-1])

    def on_end(self, event: numba_event.Event) -> None:
        self._depth -= 1
        if self._depth == 0:
            self._log.warning("%s: compiled %s in %.1f s", self.prog, self.compiled[-1],
                              time.monotonic() - self._t0)

    def close(self) -> None:
        """Stop watching."""
        numba_event.unregister("numba:compile", self)


def _signature(data: dict) -> str:
    func = data["dispatcher"].py_func
    return f"{func.__module__}.{func.__qualname__}({', '.join(str(a) for a in data['args'])})"


def watch_late_compiles(prog: str, logger: logging.Logger) -> LateCompiles:
    """Announce and record every numba compile from now on (call after the warm-up, before the
    ready line)."""
    watch = LateCompiles(prog, logger)
    numba_event.register("numba:compile", watch)
    return watch


__all__ = ["LateCompiles", "watch_late_compiles"]
