"""COMMAND_LONG / COMMAND_ACK exchange of one vehicle: register the ACK, send, await, retry.

Every COMMAND_ACK for a command is read while its exchange is open, not only the first: PX4
v1.16.0 answers DO_SET_MODE with ACCEPTED (its MAVLink receiver) and then the commander's real
answer, so `AckLog.result` lets a later refusal win over an earlier ACCEPTED.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field

from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import MavCmd, MavResult

logger = logging.getLogger(__name__)

#: Builds and sends one COMMAND_LONG: (command, confirmation, params[7]) -> None.
SendCommand = Callable[[int, int, Sequence[float]], None]


class CommandTimeoutError(TimeoutError):
    """No final COMMAND_ACK after all attempts."""


class CommandRejectedError(RuntimeError):
    """The vehicle answered a command with a result other than ACCEPTED (the last refusal of
    every ACK read wins); `acks` lists every MAV_RESULT seen, `text` the vehicle's STATUSTEXT."""

    def __init__(self, message: str, command: int, result: MavResult,
                 acks: tuple[MavResult, ...] = (), text: str = "") -> None:
        super().__init__(message)
        self.command = command
        self.result = result
        self.acks = acks or (result,)
        self.text = text


class CommandNotConfirmedError(TimeoutError):
    """The command was accepted, but the vehicle's HEARTBEAT did not show its effect in time."""

    def __init__(self, message: str, command: int, acks: tuple[MavResult, ...] = (),
                 text: str = "") -> None:
        super().__init__(message)
        self.command = command
        self.acks = acks
        self.text = text


@dataclass(frozen=True, slots=True)
class CommandStats:
    sent: int = 0  # COMMAND_LONG packets, retries included
    retries: int = 0
    timeouts: int = 0  # commands that raised CommandTimeoutError
    acks_unexpected: int = 0  # COMMAND_ACK with no command waiting (late or duplicate)
    acks_for_others: int = 0  # COMMAND_ACK addressed to another GCS


@dataclass(slots=True)
class AckLog:
    """Every COMMAND_ACK received for one command while its exchange is open, in order."""

    command: int
    first: asyncio.Future[MavResult]  # the first final (not IN_PROGRESS) result
    results: list[MavResult] = field(default_factory=list)
    changed: asyncio.Event = field(default_factory=asyncio.Event)  # set on every ACK
    in_progress: bool = False

    @property
    def result(self) -> MavResult | None:
        """The answer: the last final result other than ACCEPTED if any (a later refusal wins),
        else ACCEPTED if one came, else None."""
        finals = [r for r in self.results if r != MavResult.IN_PROGRESS]
        refusals = [r for r in finals if r != MavResult.ACCEPTED]
        if refusals:
            return refusals[-1]
        return MavResult.ACCEPTED if finals else None

    def summary(self) -> str:
        """'ACCEPTED, TEMPORARILY_REJECTED', or 'none'."""
        return ", ".join(r.name for r in self.results) or "none"



def command_label(command: int) -> str:
    """'MAV_CMD_COMPONENT_ARM_DISARM (400)' for known commands, 'MAV_CMD 1234' otherwise."""
    try:
        return f"MAV_CMD_{MavCmd(command).name} ({command})"
    except ValueError:
        return f"MAV_CMD {command}"


class CommandChannel:
    """Pending-ACK registry and retry loop for one vehicle (``name`` prefixes every message)."""

    def __init__(self, name: str, gcs_sysid: int, send: SendCommand) -> None:
        self._name = name
        self._gcs_sysid = gcs_sysid
        self._send = send
        self._pending: dict[int, AckLog] = {}
        self._locks: dict[int, asyncio.Lock] = {}
        self._n = {"sent": 0, "retries": 0, "timeouts": 0, "acks_unexpected": 0,
                   "acks_for_others": 0}

    def stats(self) -> CommandStats:
        return CommandStats(**self._n)

    def on_ack(self, msg: MAVLinkMessage) -> None:
        """Feed a COMMAND_ACK from the vehicle; returns immediately."""
        if msg.target_system not in (0, self._gcs_sysid):
            self._n["acks_for_others"] += 1
            return
        pending = self._pending.get(msg.command)
        if pending is None:
            self._n["acks_unexpected"] += 1
            return
        try:
            result = MavResult(msg.result)
        except ValueError:
            logger.warning("%s: COMMAND_ACK for %s with unknown result %d, taken as FAILED",
                           self._name, command_label(msg.command), msg.result)
            result = MavResult.FAILED
        if pending.first.done():
            logger.info("%s: %s answered again: %s (COMMAND_ACKs %s)", self._name,
                        command_label(msg.command), result.name,
                        ", ".join(r.name for r in [*pending.results, result]))
        pending.results.append(result)
        pending.changed.set()
        if result == MavResult.IN_PROGRESS:
            pending.in_progress = True
            return
        if not pending.first.done():
            pending.first.set_result(result)

    @contextlib.asynccontextmanager
    async def exchange(self, command: int) -> AsyncIterator[AckLog]:
        """Register an AckLog for `command` (serialised per command id, so ACKs cannot be
        confused); every ACK for it is recorded until the block exits."""
        async with self._locks.setdefault(command, asyncio.Lock()):
            log = AckLog(command, asyncio.get_running_loop().create_future())
            self._pending[command] = log
            try:
                yield log
            finally:
                del self._pending[command]
                if not log.first.done():
                    log.first.cancel()

    async def send_until_acked(self, log: AckLog, params: Sequence[float] = (), *,
                               timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """Send `log.command` and return its first final MAV_RESULT (returns when acked).

        An attempt without ACK within ``timeout_s`` is resent with ``confirmation`` + 1, at most
        ``retries`` times; an IN_PROGRESS ACK is not final, and the next attempt waits again
        without resending. Raises CommandTimeoutError naming vehicle and command."""
        command = log.command
        if len(params) > 7:
            raise ValueError(f"{self._name}: COMMAND_LONG takes 7 params, got {len(params)}")
        if retries < 0 or not timeout_s > 0:
            raise ValueError(f"{self._name}: need retries >= 0 and timeout_s > 0, "
                             f"got {retries}, {timeout_s}")
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        label = command_label(command)
        for attempt in range(retries + 1):
            if attempt > 0:
                self._n["retries"] += 1
            if not log.in_progress:
                self._send(command, attempt, p)
                self._n["sent"] += 1
            try:
                async with asyncio.timeout(timeout_s):
                    return await asyncio.shield(log.first)
            except TimeoutError:
                logger.debug("%s: %s attempt %d timed out", self._name, label, attempt + 1)
        self._n["timeouts"] += 1
        raise CommandTimeoutError(
            f"{self._name}: {label} got no COMMAND_ACK in {retries + 1} attempts of {timeout_s} s")

    async def command_long(self, command: int, params: Sequence[float] = (), *,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """Send COMMAND_LONG and return the MAV_RESULT of its COMMAND_ACK (returns when done).

        The ACK is registered before the first send. An attempt without ACK within ``timeout_s``
        is resent with ``confirmation`` + 1, at most ``retries`` times; an IN_PROGRESS ACK is not
        final, and the next attempt waits again without resending. Raises CommandTimeoutError
        naming vehicle and command when every attempt timed out. Commands with the same id are
        serialised so that their ACKs cannot be confused.
        """
        async with self.exchange(command) as log:
            return await self.send_until_acked(log, params, timeout_s=timeout_s, retries=retries)
