"""What a proxy asks its vehicle and awaits: next messages, confirmed commands, params, version.

`MessageWaiters` are woken by the proxy's receive path; `VehicleCommands` sends through the
proxy's send path and reads its STATUSTEXT log and latest HEARTBEAT. Both log as the proxy.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable, Collection, Iterator, Sequence

from gcs.link.codec import MavlinkCodec, MAVLinkMessage, mavlink, message_name
from gcs.link.commands import (
    AckLog,
    CommandChannel,
    CommandNotConfirmedError,
    CommandRejectedError,
    CommandStats,
    CommandTimeoutError,
    Liveness,
    command_label,
)
from gcs.link.config import VehicleLinkConfig
from gcs.link.enums import MavCmd, MavModeFlag, MavResult
from gcs.link.statustext import StatusTextLog
from gcs.link.telemetry import Received
from gcs.link.udp import LinkClosedError

logger = logging.getLogger("gcs.link.proxy")  # the records of the proxy these serve

AUTOPILOT_VERSION_ID = 148  # REQUEST_MESSAGE param1
FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2 forcing arm/disarm (PX4; ArduPilot disarm)
#: A command is not confirmed once its timeout has passed AND this many HEARTBEATs received
#: after its ACK did not show the effect; with fewer heard (a lossy link), the wait goes on up to
#: CONFIRM_LOSSY_FACTOR x the timeout (command_confirmed).
CONFIRM_DENIALS = 2
CONFIRM_LOSSY_FACTOR = 3.0


class ParamTimeoutError(TimeoutError):
    """No PARAM_VALUE answered a PARAM_REQUEST_READ after all attempts."""


class MessageWaiters:
    """Who waits for one vehicle's next accepted message of a type (``name`` prefixes every
    message): registered before the request that brings it is sent, woken by `wake`."""

    def __init__(self, name: str) -> None:
        self._name = name
        self._entries: list[
            tuple[str, Callable[[MAVLinkMessage], bool], asyncio.Future[Received]]] = []

    def __bool__(self) -> bool:
        return bool(self._entries)

    def wants(self, kind: str) -> bool:
        return any(w[0] == kind for w in self._entries)

    def wants_any(self, kinds: Collection[str]) -> bool:
        entries = self._entries  # asked for every vehicle at every batch: none is the rule
        return bool(entries) and any(w[0] in kinds for w in entries)

    @contextlib.contextmanager
    def registered(self, kind: str, predicate: Callable[[MAVLinkMessage], bool] | None = None
                   ) -> Iterator[asyncio.Future[Received]]:
        """A future for the next ``kind`` message matching ``predicate``, woken until the block
        exits (then cancelled if still pending)."""
        fut: asyncio.Future[Received] = asyncio.get_running_loop().create_future()
        entry = (kind, predicate or (lambda _m: True), fut)
        self._entries.append(entry)
        try:
            yield fut
        finally:
            if entry in self._entries:
                self._entries.remove(entry)
            if not fut.done():
                fut.cancel()

    async def wait(self, kind: str, timeout_s: float,
                   predicate: Callable[[MAVLinkMessage], bool] | None = None) -> Received:
        """The next ``kind`` message matching ``predicate``; returns when it arrives, raises
        TimeoutError naming the vehicle after ``timeout_s``."""
        with self.registered(kind, predicate) as fut:
            try:
                async with asyncio.timeout(timeout_s):
                    return await fut
            except TimeoutError:
                raise TimeoutError(f"{self._name}: no {kind} within {timeout_s} s") from None

    def wake(self, msg: MAVLinkMessage, now_s: float) -> None:
        """``msg``, received at ``now_s``, ends every wait it matches."""
        kind = msg.get_type()
        for entry in list(self._entries):
            want, pred, fut = entry
            if want == kind and not fut.done() and pred(msg):
                fut.set_result(Received(msg, now_s))
                self._entries.remove(entry)

    def close(self) -> None:
        """The link closed: every wait raises LinkClosedError."""
        for _, _, fut in self._entries:
            if not fut.done():
                fut.set_exception(LinkClosedError(f"{self._name}: link closed while waiting"))
        self._entries.clear()


class VehicleCommands:
    """One vehicle's commands that wait for an answer: COMMAND_LONG (its ACK exchange:
    `CommandChannel`) and the helpers built on it (arm, disarm, modes, takeoff, land), commands
    confirmed by HEARTBEAT, PARAM_REQUEST_READ, AUTOPILOT_VERSION and SET_MESSAGE_INTERVAL
    (``on_stream_set`` hears the name of each stream whose new rate was accepted). Messages are
    built with ``codec`` and handed to ``send``; every method returns when answered.

    The helpers (`arm` ... `land`) take ``check``: raise CommandRejectedError naming the vehicle
    and command unless the answer is ACCEPTED; ``timeout_s``/``retries`` as in `command_long`."""

    def __init__(self, name: str, config: VehicleLinkConfig, codec: MavlinkCodec,
                 send: Callable[[MAVLinkMessage], object], *, liveness: Liveness,
                 waiters: MessageWaiters, statustexts: StatusTextLog,
                 latest: Callable[[str], Received | None],
                 on_stream_set: Callable[[str], None] | None = None) -> None:
        self._name = name
        self._sysid = config.sysid
        self._compid = config.compid
        self._codec = codec
        self._send = send
        self._liveness = liveness
        self._waiters = waiters
        self._statustexts = statustexts
        self._latest = latest
        self._on_stream_set = on_stream_set
        self._channel = CommandChannel(name, config.gcs_sysid, self._send_command,
                                       liveness=liveness, silent_wait_s=config.silent_wait_s)

    def stats(self) -> CommandStats:
        return self._channel.stats()

    def on_ack(self, msg: MAVLinkMessage) -> None:
        """Feed a COMMAND_ACK from the vehicle; returns immediately."""
        self._channel.on_ack(msg)

    async def command_long(self, command: int, params: Sequence[float] = (), *,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """Send COMMAND_LONG, return the MAV_RESULT of its COMMAND_ACK (returns when done;
        details: CommandChannel.command_long)."""
        return await self._channel.command_long(command, params, timeout_s=timeout_s,
                                                retries=retries)

    async def checked(self, command: MavCmd, params: Sequence[float], check: bool,
                      timeout_s: float, retries: int) -> MavResult:
        """`command_long`; with ``check``, a result other than ACCEPTED raises
        CommandRejectedError naming the vehicle and command."""
        result = await self.command_long(command, params, timeout_s=timeout_s, retries=retries)
        if check and result != MavResult.ACCEPTED:
            raise CommandRejectedError(
                f"{self._name}: {command_label(command)} answered {result.name}", command, result)
        return result

    async def arm(self, *, force: bool = False, check: bool = True, timeout_s: float = 0.5,
                  retries: int = 2) -> MavResult:
        """Arm (COMPONENT_ARM_DISARM 400; force: param2 = FORCE_MAGIC)."""
        return await self.checked(MavCmd.COMPONENT_ARM_DISARM,
                                  [1.0, FORCE_MAGIC if force else 0.0], check, timeout_s, retries)

    async def disarm(self, *, force: bool = False, check: bool = True, timeout_s: float = 0.5,
                     retries: int = 2) -> MavResult:
        """Disarm (force: also in the air)."""
        return await self.checked(MavCmd.COMPONENT_ARM_DISARM,
                                  [0.0, FORCE_MAGIC if force else 0.0], check, timeout_s, retries)

    async def set_mode_px4(self, main_mode: int, sub_mode: int = 0, *, check: bool = True,
                           timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """PX4 mode via DO_SET_MODE (176): param1 = CUSTOM_MODE_ENABLED (+ SAFETY_ARMED if the
        latest HEARTBEAT says armed), param2 = main mode, param3 = sub mode."""
        hb = self._latest("HEARTBEAT")
        armed = hb is not None and bool(hb.msg.base_mode & MavModeFlag.SAFETY_ARMED)
        base = MavModeFlag.CUSTOM_MODE_ENABLED | (MavModeFlag.SAFETY_ARMED if armed else 0)
        return await self.checked(MavCmd.DO_SET_MODE, [float(base), main_mode, sub_mode], check,
                                  timeout_s, retries)

    async def set_mode_ardupilot(self, mode: int, *, check: bool = True, timeout_s: float = 0.5,
                                 retries: int = 2) -> MavResult:
        """ArduPilot mode number (e.g. GUIDED 4) via DO_SET_MODE."""
        return await self.checked(MavCmd.DO_SET_MODE,
                                  [float(MavModeFlag.CUSTOM_MODE_ENABLED), mode], check,
                                  timeout_s, retries)

    async def takeoff(self, altitude_m: float = math.nan, *, check: bool = True,
                      timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """NAV_TAKEOFF (22) with param7 = altitude (PX4: AMSL, NaN = MIS_TAKEOFF_ALT; ArduPilot:
        relative to home); answered when accepted, not when the vehicle reached it."""
        return await self.checked(
            MavCmd.NAV_TAKEOFF, [0, 0, 0, math.nan, math.nan, math.nan, altitude_m], check,
            timeout_s, retries)

    async def land(self, *, check: bool = True, timeout_s: float = 0.5,
                   retries: int = 2) -> MavResult:
        """NAV_LAND (21) here (lat/lon/yaw NaN); answered when accepted, not when landed."""
        return await self.checked(
            MavCmd.NAV_LAND, [0, 0, 0, math.nan, math.nan, math.nan, 0], check, timeout_s,
            retries)

    async def command_confirmed(self, command: int, params: Sequence[float], *, want: str,
                                shows: Callable[[MAVLinkMessage], bool],
                                reported: Callable[[MAVLinkMessage | None], str],
                                timeout_s: float = 3.0, ack_timeout_s: float = 0.5,
                                retries: int = 2) -> tuple[MavResult, ...]:
        """Send COMMAND_LONG and return when the vehicle's HEARTBEAT shows its effect; returns
        every MAV_RESULT read for it.

        The ACK is registered before sending (resends as in ``command_long``). Every ACK that
        arrives until the confirmation is read, and a refusal among them wins over an earlier
        ACCEPTED (PX4 v1.16.0 sends ACCEPTED, then the real answer): CommandRejectedError. The
        effect counts only in a HEARTBEAT received after the first final ACK for which
        ``shows(heartbeat)`` is true. It is not confirmed (CommandNotConfirmedError) once
        ``timeout_s`` has passed since that ACK and at least CONFIRM_DENIALS HEARTBEATs since it
        did not show the effect: what the vehicle said, not what the link lost. With fewer heard
        the wait goes on, up to CONFIRM_LOSSY_FACTOR x ``timeout_s`` (at 20 % loss all three of
        PX4's 1 Hz HEARTBEATs in 3 s are lost 0.8 % of the time; all nine in 9 s, 5e-7). Both
        messages name the vehicle, ``want`` (e.g. 'mode OFFBOARD'), what the latest HEARTBEAT
        reports (``reported``), the ACKs seen, and the vehicle's latest STATUSTEXT since the
        command was sent."""
        loop = asyncio.get_running_loop()
        sent_s = self._liveness.now_s()
        label = command_label(command)
        async with self._channel.exchange(command) as log:
            await self._channel.send_until_acked(log, params, timeout_s=ack_timeout_s,
                                                 retries=retries)
            acked_at = loop.time()
            deadline = acked_at + CONFIRM_LOSSY_FACTOR * timeout_s
            denials = 0  # HEARTBEATs after the ACK that did not show the effect
            while True:
                result = log.result
                if result is not None and result != MavResult.ACCEPTED:
                    await self._settle_text(sent_s)
                    raise CommandRejectedError(
                        self._unconfirmed_text(f"{label} for {want} refused", log, reported,
                                               sent_s), command, result, tuple(log.results),
                        self._text_since(sent_s))
                now = loop.time()
                if (now >= acked_at + timeout_s and denials >= CONFIRM_DENIALS) or now >= deadline:
                    why = (f"{want} not confirmed within {timeout_s:g} s" if denials >=
                           CONFIRM_DENIALS else f"{want} not confirmed within "
                           f"{CONFIRM_LOSSY_FACTOR * timeout_s:g} s ({denials} HEARTBEAT"
                           f"{'' if denials == 1 else 's'} heard after the ACK)")
                    raise CommandNotConfirmedError(
                        self._unconfirmed_text(why, log, reported, sent_s),
                        command, tuple(log.results), self._text_since(sent_s))
                remaining = (deadline if denials < CONFIRM_DENIALS else
                             max(acked_at + timeout_s, now + 1e-3)) - now
                log.changed.clear()
                heartbeat = asyncio.ensure_future(self._waiters.wait("HEARTBEAT", remaining))
                acked = asyncio.ensure_future(log.changed.wait())
                try:
                    await asyncio.wait({heartbeat, acked}, timeout=remaining,
                                       return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for fut in (heartbeat, acked):
                        if not fut.done():
                            fut.cancel()
                    await asyncio.gather(heartbeat, acked, return_exceptions=True)
                if heartbeat.done() and not heartbeat.cancelled() and heartbeat.exception() is None:
                    if shows(heartbeat.result().msg) and log.result == MavResult.ACCEPTED:
                        return tuple(log.results)
                    denials += 1

    def _text_since(self, since_s: float) -> str:
        text = self._statustexts.latest(since_s)
        return text.text if text is not None else ""

    async def _settle_text(self, since_s: float, timeout_s: float = 0.2) -> None:
        """A refusal's STATUSTEXT may follow its ACK (PX4, ArduPilot): wait briefly for it."""
        if self._statustexts.latest(since_s) is None:
            with contextlib.suppress(TimeoutError):
                await self._waiters.wait("STATUSTEXT", timeout_s)

    def _unconfirmed_text(self, what: str, log: AckLog,
                          reported: Callable[[MAVLinkMessage | None], str], since_s: float) -> str:
        hb = self._latest("HEARTBEAT")
        text = self._statustexts.latest(since_s)
        said = f"; the vehicle said {text.quoted()}" if text is not None else ""
        return (f"{self._name}: {what}: HEARTBEAT reports {reported(hb.msg if hb else None)}; "
                f"COMMAND_ACKs seen: {log.summary()}{said}")

    def _send_command(self, command: int, confirmation: int, params: Sequence[float]) -> None:
        self._send(self._codec.mav.command_long_encode(
            self._sysid, self._compid, command, confirmation, *params))

    async def param_read(self, name: str, timeout_s: float = 0.5, retries: int = 2) -> float:
        """Read one parameter: PARAM_REQUEST_READ by id (param_index -1), returns the value of the
        matching PARAM_VALUE (as the autopilot sends it: ArduPilot casts integers to float).

        The reply is awaited before the first send; an attempt without reply within ``timeout_s``
        is resent, at most ``retries`` times (a late reply to an earlier attempt still counts);
        then raises ParamTimeoutError (a TimeoutError) naming vehicle and parameter."""
        if not 1 <= len(name) <= 16 or not name.isascii():
            raise ValueError(f"{self._name}: parameter id: expected 1-16 ASCII characters, got "
                             f"{name!r}")
        if retries < 0 or not timeout_s > 0:
            raise ValueError(f"{self._name}: need retries >= 0 and timeout_s > 0, "
                             f"got {retries}, {timeout_s}")
        with self._waiters.registered("PARAM_VALUE", lambda m: str(m.param_id) == name) as fut:
            for _ in range(retries + 1):
                self._send(self._codec.mav.param_request_read_encode(
                    self._sysid, self._compid, name.encode("ascii"), -1))
                try:
                    async with asyncio.timeout(timeout_s):
                        received = await asyncio.shield(fut)
                    return float(received.msg.param_value)
                except TimeoutError:
                    logger.debug("%s: PARAM_REQUEST_READ %s timed out", self._name, name)
        raise ParamTimeoutError(f"{self._name}: PARAM_REQUEST_READ {name} got no PARAM_VALUE in "
                                f"{retries + 1} attempts of {timeout_s} s")

    async def autopilot_version(self, timeout_s: float = 1.0, retries: int = 2) -> int:
        """AUTOPILOT_VERSION.flight_sw_version (major << 24 | minor << 16 | patch << 8 | type),
        asked for with REQUEST_MESSAGE (148). The reply is awaited before the request is sent;
        raises CommandRejectedError if the request is refused, TimeoutError naming the vehicle
        if no AUTOPILOT_VERSION arrives."""
        with self._waiters.registered("AUTOPILOT_VERSION") as fut:
            try:
                await self.checked(MavCmd.REQUEST_MESSAGE, (AUTOPILOT_VERSION_ID,), True,
                                   timeout_s, retries)
                async with asyncio.timeout(timeout_s):
                    received = await fut
                return int(received.msg.flight_sw_version)
            except TimeoutError:
                raise TimeoutError(f"{self._name}: no AUTOPILOT_VERSION within {timeout_s} s of "
                                   "an accepted REQUEST_MESSAGE") from None

    async def set_message_interval(self, msg_id: int, rate_hz: float, *, check: bool = True,
                                   timeout_s: float = 0.5, retries: int = 2) -> MavResult:
        """SET_MESSAGE_INTERVAL (511): rate_hz > 0 sets 1e6/rate_hz us, 0 disables the stream;
        returns when acknowledged. A refusal (``check``) or no ACK raises an error naming the
        vehicle, the message and the rate: `vehicle 2 (sysid 2): stream EXTENDED_SYS_STATE (245)
        at 5 Hz: SET_MESSAGE_INTERVAL answered DENIED`."""
        if not math.isfinite(rate_hz) or rate_hz < 0:
            raise ValueError(f"{self._name}: message {msg_id} rate_hz: expected >= 0, "
                             f"got {rate_hz}")
        interval_us = -1.0 if rate_hz == 0 else 1e6 / rate_hz
        what = f"{self._name}: stream {message_name(msg_id)} at {rate_hz:g} Hz"
        try:
            result = await self.command_long(MavCmd.SET_MESSAGE_INTERVAL, [msg_id, interval_us],
                                             timeout_s=timeout_s, retries=retries)
        except CommandTimeoutError as exc:
            raise CommandTimeoutError(f"{what}: SET_MESSAGE_INTERVAL {exc.reason}",
                                      exc.reason) from None
        if check and result != MavResult.ACCEPTED:
            raise CommandRejectedError(f"{what}: SET_MESSAGE_INTERVAL answered {result.name}",
                                       MavCmd.SET_MESSAGE_INTERVAL, result)
        msg_type = mavlink.mavlink_map.get(msg_id)
        if result == MavResult.ACCEPTED and msg_type is not None and self._on_stream_set:
            self._on_stream_set(msg_type.msgname)  # the rate asked for is measured from here on
        return result
