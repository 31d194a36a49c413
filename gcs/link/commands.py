"""COMMAND_LONG / COMMAND_ACK exchange of one vehicle: register the ACK, send, await, retry.

Every COMMAND_ACK for a command is read while its exchange is open, not only the first: PX4
v1.16.0 answers DO_SET_MODE with ACCEPTED (its MAVLink receiver) and then the commander's real
answer, so `AckLog.result` lets a later refusal win over an earlier ACCEPTED.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import MavCmd, MavResult

logger = logging.getLogger(__name__)

#: Builds and sends one COMMAND_LONG: (command, confirmation, params[7]) -> None.
SendCommand = Callable[[int, int, Sequence[float]], None]

_VOICE_POLL_S = 0.05  # how often a wait for a silent vehicle looks for its next message
#: A vehicle is silent once nothing at all came from it for this long: longer than the period of
#: a 1 Hz HEARTBEAT, all that a vehicle may send before its streams are asked for.
SILENT_AFTER_S = 1.5


class Liveness(Protocol):
    """When the vehicle was last heard, on one clock [s] (the proxy's)."""

    def now_s(self) -> float: ...

    def last_heard_s(self) -> float:
        """Receive time of the vehicle's latest message of any type; -inf before the first."""
        ...

    def up_since_s(self) -> float:
        """When its link came up (the origin of the times in messages)."""
        ...


class CommandTimeoutError(TimeoutError):
    """No final COMMAND_ACK after all attempts; ``reason`` is the message without the vehicle
    and command ('got no COMMAND_ACK in 3 attempts of 0.5 s')."""

    def __init__(self, message: str, reason: str = "") -> None:
        super().__init__(message)
        self.reason = reason or message


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
    silent_waits: int = 0  # commands that waited for a vehicle that had fallen silent


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

    def __init__(self, name: str, gcs_sysid: int, send: SendCommand, *,
                 liveness: Liveness | None = None, silent_wait_s: float = 0.0) -> None:
        self._name = name
        self._gcs_sysid = gcs_sysid
        self._send = send
        self._liveness = liveness
        self._silent_wait_s = silent_wait_s
        self._pending: dict[int, AckLog] = {}
        self._locks: dict[int, asyncio.Lock] = {}
        self._n = {"sent": 0, "retries": 0, "timeouts": 0, "acks_unexpected": 0,
                   "acks_for_others": 0, "silent_waits": 0}

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
        waited = False
        while True:
            sent_s = self._liveness.now_s() if self._liveness is not None else 0.0
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
            quiet_since = None if waited else await self._quiet_since(log, sent_s)
            if log.first.done():  # answered while it was told from a silence
                return log.first.result()
            if quiet_since is None:
                break
            # alive but silent (compiling, starting, paused): nothing at all came back since
            # it fell silent, so nothing was refused; wait for it to speak, then ask again (once)
            waited = True
            self._n["silent_waits"] += 1
            silence = quiet_since - self._liveness.up_since_s()
            if not await self._await_voice(label, quiet_since, silence):
                self._n["timeouts"] += 1
                reason = (f"got no COMMAND_ACK: the vehicle, heard at {silence:.2f} s, sent "
                          f"nothing at all for {self._silent_wait_s:g} s more (alive before, "
                          "silent since; not a refusal)")
                raise CommandTimeoutError(f"{self._name}: {label} {reason}", reason)
        self._n["timeouts"] += 1
        reason = f"got no COMMAND_ACK in {retries + 1} attempts of {timeout_s:g} s"
        raise CommandTimeoutError(f"{self._name}: {label} {reason}", reason)

    async def _quiet_since(self, log: AckLog, sent_s: float) -> float | None:
        """When the vehicle was last heard, if nothing at all came from it for `SILENT_AFTER_S`
        since. One heard before the command (sent at ``sent_s``) and not since is judged now;
        one that spoke after it and then stopped (a stall) is given the rest of that span,
        which an ACK or any message ends. None: it spoke, or too little time passed to tell, or
        it was never heard (no excuse)."""
        live = self._liveness
        if live is None or not self._silent_wait_s > 0.0:
            return None
        last = live.last_heard_s()
        if not math.isfinite(last) or (last < sent_s and live.now_s() - last < SILENT_AFTER_S):
            return None
        while live.now_s() - last < SILENT_AFTER_S:
            if log.first.done() or live.last_heard_s() > last:
                return None
            await asyncio.sleep(_VOICE_POLL_S)
        return last if live.last_heard_s() <= last else None

    async def _await_voice(self, label: str, last_s: float, heard_at_s: float) -> bool:
        """Wait, at most `silent_wait_s`, until anything arrives from the vehicle after the
        message it sent at ``last_s``; says so when it starts. True if the vehicle spoke."""
        live = self._liveness
        assert live is not None
        logger.warning("%s: %s unanswered: heard at %.2f s, silent since; waiting up to %g s "
                       "for it to speak (a vehicle program that is compiling or starting is "
                       "silent, not refusing)", self._name, label, heard_at_s,
                       self._silent_wait_s)
        deadline = asyncio.get_running_loop().time() + self._silent_wait_s
        while asyncio.get_running_loop().time() < deadline:
            if live.last_heard_s() > last_s:
                logger.warning("%s: heard again after %.1f s of silence; asking again",
                               self._name, live.now_s() - live.up_since_s() - heard_at_s)
                return True
            await asyncio.sleep(_VOICE_POLL_S)
        return live.last_heard_s() > last_s

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
