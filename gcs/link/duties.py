"""A proxy's periodic duties: the ground station's HEARTBEAT, TIMESYNC requests, the link check.

Each runs as an asyncio task at phase ``phase`` (0..1) of its period. Proxies spread their
phases by slot (`slot_phase`), so a team's hundreds of proxies do not all send and check in the
same event-loop pass and stall the tick for milliseconds.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

logger = logging.getLogger("gcs.link.proxy")  # the records of the proxy these serve

#: The golden ratio's fraction: slot k's periodic tasks run at phase k x this (mod 1).
_GOLDEN = 0.6180339887498949


def slot_phase(slot: int | None) -> float:
    """Phase of slot ``slot``'s duties (golden-ratio steps: even for any team size)."""
    return ((slot or 0) * _GOLDEN) % 1.0


class LinkDuties:
    """The periodic tasks of vehicle link ``name``: ``heartbeat`` every ``heartbeat_period_s``
    (the first at `start`), ``timesync`` every ``timesync_period_s`` (none if 0) and ``check``
    every ``check_period_s``. A duty that raises is logged; the others go on."""

    def __init__(self, name: str, *, phase: float, heartbeat: Callable[[], None],
                 heartbeat_period_s: float, timesync: Callable[[], None],
                 timesync_period_s: float, check: Callable[[], None],
                 check_period_s: float) -> None:
        self._name = name
        self._phase = phase
        self._heartbeat = heartbeat
        self._heartbeat_period_s = heartbeat_period_s
        self._timesync = timesync
        self._timesync_period_s = timesync_period_s
        self._check = check
        self._check_period_s = check_period_s
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        """Send the first HEARTBEAT now and start the tasks; returns immediately."""
        self._heartbeat()
        self._tasks = [
            asyncio.create_task(self._heartbeat_loop(), name=f"{self._name} heartbeat"),
            asyncio.create_task(self._every(self._check, self._check_period_s),
                                name=f"{self._name} link monitor"),
        ]
        if self._timesync_period_s > 0.0:
            self._tasks.append(asyncio.create_task(
                self._every(self._timesync, self._timesync_period_s),
                name=f"{self._name} timesync"))
        for task in self._tasks:
            task.add_done_callback(self._on_task_done)

    async def stop(self) -> None:
        """Cancel the tasks; returns when they have ended."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []

    async def _heartbeat_loop(self) -> None:
        loop = asyncio.get_running_loop()
        period = self._heartbeat_period_s
        next_s = loop.time() + (self._phase - 1.0) * period  # the first went out at start
        while True:
            next_s = max(next_s + period, loop.time())
            await asyncio.sleep(next_s - loop.time())
            self._heartbeat()

    async def _every(self, duty: Callable[[], None], period_s: float) -> None:
        await asyncio.sleep(self._phase * period_s)
        while True:
            duty()
            await asyncio.sleep(period_s)

    def _on_task_done(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            logger.error("%s: task %s failed", self._name, task.get_name(),
                         exc_info=task.exception())
