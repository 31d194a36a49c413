"""COMMAND_LONG / COMMAND_ACK exchange of one vehicle: register the ACK, send, await, retry."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import MavCmd, MavResult

logger = logging.getLogger(__name__)

#: Builds and sends one COMMAND_LONG: (command, confirmation, params[7]) -> None.
SendCommand = Callable[[int, int, Sequence[float]], None]


class CommandTimeoutError(TimeoutError):
    """No final COMMAND_ACK after all attempts."""


class CommandRejectedError(RuntimeError):
    """The vehicle answered a command with a result other than ACCEPTED."""

    def __init__(self, message: str, command: int, result: MavResult) -> None:
        super().__init__(message)
        self.command = command
        self.result = result


@dataclass(frozen=True, slots=True)
class CommandStats:
    sent: int = 0  # COMMAND_LONG packets, retries included
    retries: int = 0
    timeouts: int = 0  # commands that raised CommandTimeoutError
    acks_unexpected: int = 0  # COMMAND_ACK with no command waiting (late or duplicate)
    acks_for_others: int = 0  # COMMAND_ACK addressed to another GCS


@dataclass(slots=True)
class _PendingAck:
    future: asyncio.Future[MavResult]
    in_progress: bool = False


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
        self._pending: dict[int, _PendingAck] = {}
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
        if pending is None or pending.future.done():
            self._n["acks_unexpected"] += 1
            return
        try:
            result = MavResult(msg.result)
        except ValueError:
            logger.warning("%s: COMMAND_ACK for %s with unknown result %d, taken as FAILED",
                           self._name, command_label(msg.command), msg.result)
            result = MavResult.FAILED
        if result == MavResult.IN_PROGRESS:
            pending.in_progress = True
            return
        pending.future.set_result(result)

    async def command_long(self, command: int, params: Sequence[float] = (), *,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """Send COMMAND_LONG and return the MAV_RESULT of its COMMAND_ACK (returns when done).

        The ACK is registered before the first send. An attempt without ACK within ``timeout_s``
        is resent with ``confirmation`` + 1, at most ``retries`` times; an IN_PROGRESS ACK is not
        final, and the next attempt waits again without resending. Raises CommandTimeoutError
        naming vehicle and command when every attempt timed out. Commands with the same id are
        serialised so that their ACKs cannot be confused.
        """
        if len(params) > 7:
            raise ValueError(f"{self._name}: COMMAND_LONG takes 7 params, got {len(params)}")
        if retries < 0 or not timeout_s > 0:
            raise ValueError(f"{self._name}: need retries >= 0 and timeout_s > 0, "
                             f"got {retries}, {timeout_s}")
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        label = command_label(command)
        async with self._locks.setdefault(command, asyncio.Lock()):
            pending = _PendingAck(asyncio.get_running_loop().create_future())
            self._pending[command] = pending
            try:
                for attempt in range(retries + 1):
                    if attempt > 0:
                        self._n["retries"] += 1
                    if not pending.in_progress:
                        self._send(command, attempt, p)
                        self._n["sent"] += 1
                    try:
                        async with asyncio.timeout(timeout_s):
                            return await asyncio.shield(pending.future)
                    except TimeoutError:
                        logger.debug("%s: %s attempt %d timed out", self._name, label, attempt + 1)
            finally:
                del self._pending[command]
        self._n["timeouts"] += 1
        raise CommandTimeoutError(
            f"{self._name}: {label} got no COMMAND_ACK in {retries + 1} attempts of {timeout_s} s")
