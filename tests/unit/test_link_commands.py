"""COMMAND_LONG/ACK channel without sockets: registration order, retries, timeout, IN_PROGRESS."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.commands import AckLog, CommandChannel, CommandTimeoutError, command_label
from gcs.link.enums import MavCmd, MavResult

VEHICLE = mavlink.MAVLink(None, 1, 1)
ARM = MavCmd.COMPONENT_ARM_DISARM


def run(coro: Coroutine[Any, Any, Any], timeout_s: float = 5.0) -> Any:
    async def bounded() -> Any:
        async with asyncio.timeout(timeout_s):
            return await coro
    return asyncio.run(bounded())


def ack(command: int, result: int, target_system: int = 255) -> mavlink.MAVLink_message:
    return VEHICLE.command_ack_encode(command, result, 0, 0, target_system, 190)


class Vehicle:
    """Records every COMMAND_LONG and answers from inside send() as its policy says."""

    def __init__(self, policy: Callable[[int, int], Sequence[int]]) -> None:
        self.sent: list[tuple[int, int, list[float]]] = []
        self.policy = policy  # (command, confirmation) -> results to ack with, in order
        self.channel = CommandChannel("vehicle 0 (sysid 1)", 255, self.send)

    def send(self, command: int, confirmation: int, params: Sequence[float]) -> None:
        self.sent.append((command, confirmation, list(params)))
        for result in self.policy(command, confirmation):
            self.channel.on_ack(ack(command, result))


def test_ack_is_registered_before_sending() -> None:
    # GIVEN a vehicle that ACKs synchronously, inside the send call
    vehicle = Vehicle(lambda c, n: [MavResult.ACCEPTED])
    # WHEN arming THEN the ACK is matched (it would be "unexpected" if registered after sending)
    result = run(vehicle.channel.command_long(ARM, [1.0]))
    assert result == MavResult.ACCEPTED
    assert vehicle.sent == [(ARM, 0, [1.0, 0, 0, 0, 0, 0, 0])]
    assert vehicle.channel.stats().acks_unexpected == 0


def test_lost_first_ack_is_retried_with_confirmation_incremented() -> None:
    vehicle = Vehicle(lambda c, n: [] if n == 0 else [MavResult.DENIED])
    result = run(vehicle.channel.command_long(ARM, [1.0], timeout_s=0.05, retries=2))
    assert result == MavResult.DENIED
    assert [n for _, n, _ in vehicle.sent] == [0, 1]
    assert vehicle.channel.stats().retries == 1


def test_no_ack_raises_timeout_naming_vehicle_and_command() -> None:
    vehicle = Vehicle(lambda c, n: [])
    with pytest.raises(CommandTimeoutError, match=(
            r"vehicle 0 \(sysid 1\): MAV_CMD_COMPONENT_ARM_DISARM \(400\) got no COMMAND_ACK "
            r"in 3 attempts of 0\.03 s")):
        run(vehicle.channel.command_long(ARM, [1.0], timeout_s=0.03, retries=2))
    assert [n for _, n, _ in vehicle.sent] == [0, 1, 2]
    stats = vehicle.channel.stats()
    assert (stats.sent, stats.retries, stats.timeouts) == (3, 2, 1)
    assert isinstance(CommandTimeoutError("x"), TimeoutError)


def test_in_progress_is_not_final_and_is_not_resent() -> None:
    # GIVEN a vehicle that answers IN_PROGRESS, then ACCEPTED a little later
    async def scenario() -> tuple[MavResult, Vehicle]:
        vehicle = Vehicle(lambda c, n: [MavResult.IN_PROGRESS])
        loop = asyncio.get_running_loop()
        loop.call_later(0.08, vehicle.channel.on_ack, ack(ARM, MavResult.ACCEPTED))
        result = await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.05, retries=3)
        return result, vehicle
    result, vehicle = run(scenario())
    # THEN the final result is returned and the command was sent once
    assert result == MavResult.ACCEPTED
    assert len(vehicle.sent) == 1


def test_acks_for_other_gcs_and_unexpected_acks_are_counted() -> None:
    vehicle = Vehicle(lambda c, n: [])
    vehicle.channel.on_ack(ack(ARM, MavResult.ACCEPTED, target_system=245))
    vehicle.channel.on_ack(ack(ARM, MavResult.ACCEPTED))
    stats = vehicle.channel.stats()
    assert (stats.acks_for_others, stats.acks_unexpected) == (1, 1)


def test_same_command_is_serialised_and_each_call_gets_its_own_ack() -> None:
    async def scenario() -> list[MavResult]:
        results = iter([MavResult.ACCEPTED, MavResult.TEMPORARILY_REJECTED])
        vehicle = Vehicle(lambda c, n: [])
        loop = asyncio.get_running_loop()

        def answer_later(command: int, confirmation: int, params: Sequence[float]) -> None:
            vehicle.sent.append((command, confirmation, list(params)))
            loop.call_soon(vehicle.channel.on_ack, ack(command, next(results)))

        vehicle.channel._send = answer_later
        return list(await asyncio.gather(vehicle.channel.command_long(ARM, [1.0]),
                                         vehicle.channel.command_long(ARM, [1.0])))
    assert run(scenario()) == [MavResult.ACCEPTED, MavResult.TEMPORARILY_REJECTED]


def test_bad_arguments() -> None:
    vehicle = Vehicle(lambda c, n: [])
    with pytest.raises(ValueError, match="COMMAND_LONG takes 7 params, got 8"):
        run(vehicle.channel.command_long(ARM, [0.0] * 8))
    with pytest.raises(ValueError, match="need retries >= 0 and timeout_s > 0"):
        run(vehicle.channel.command_long(ARM, [], timeout_s=0.0))
    assert command_label(176) == "MAV_CMD_DO_SET_MODE (176)"
    assert command_label(31000) == "MAV_CMD 31000"


# --- every ACK is read (PX4 v1.16.0 answers DO_SET_MODE twice) ------------------------------------

MODE = MavCmd.DO_SET_MODE


def test_every_ack_of_an_exchange_is_read_and_a_later_refusal_wins() -> None:
    # GIVEN PX4 v1.16.0's pair for a refused OFFBOARD: ACCEPTED, then TEMPORARILY_REJECTED
    vehicle = Vehicle(lambda c, n: [MavResult.ACCEPTED, MavResult.TEMPORARILY_REJECTED])

    async def scenario() -> tuple[MavResult, MavResult | None, str]:
        async with vehicle.channel.exchange(MODE) as log:
            first = await vehicle.channel.send_until_acked(log, [1.0, 6.0])
            return first, log.result, log.summary()

    # THEN the first ACK alone says ACCEPTED, but the log's answer is the refusal
    first, result, summary = run(scenario())
    assert first == MavResult.ACCEPTED and result == MavResult.TEMPORARILY_REJECTED
    assert summary == "ACCEPTED, TEMPORARILY_REJECTED"
    # AND neither ACK counted as unexpected
    assert vehicle.channel.stats().acks_unexpected == 0


def test_ack_twice_and_acks_for_commands_not_asked_never_raise() -> None:
    # GIVEN a vehicle that acknowledges every command twice (ACCEPTED, ACCEPTED)
    vehicle = Vehicle(lambda c, n: [MavResult.ACCEPTED, MavResult.ACCEPTED])

    async def scenario() -> AckLog:
        async with vehicle.channel.exchange(MODE) as log:
            await vehicle.channel.send_until_acked(log)
        return log

    log = run(scenario())
    assert log.result == MavResult.ACCEPTED and log.summary() == "ACCEPTED, ACCEPTED"
    # WHEN ACKs arrive for a command nobody asked, and one with an unknown result
    vehicle.channel.on_ack(ack(MavCmd.NAV_LAND, MavResult.ACCEPTED))
    vehicle.channel.on_ack(ack(MODE, 200))
    # THEN they are counted, not raised
    assert vehicle.channel.stats().acks_unexpected == 2


def test_ack_log_result_rules() -> None:
    async def scenario() -> None:
        log = AckLog(MODE, asyncio.get_running_loop().create_future())
        assert log.result is None and log.summary() == "none"
        log.results += [MavResult.IN_PROGRESS]
        assert log.result is None
        log.results += [MavResult.ACCEPTED]
        assert log.result == MavResult.ACCEPTED
        log.results += [MavResult.DENIED, MavResult.ACCEPTED]
        assert log.result == MavResult.DENIED  # a refusal is not undone by a later ACCEPTED

    run(scenario())


class Heard:
    """A vehicle's liveness on the event loop's clock: heard at `last`, up since 0."""

    def __init__(self, last: float) -> None:
        self.last = last

    def now_s(self) -> float:
        return asyncio.get_running_loop().time() - self.t0

    def last_heard_s(self) -> float:
        return self.last

    def up_since_s(self) -> float:
        return 0.0

    def start(self) -> None:
        self.t0 = asyncio.get_running_loop().time() - 2.0  # its link came up 2 s ago
        self.last = 0.13  # and it was last heard 0.13 s after that, 1.87 s ago


def silent_vehicle(policy: Callable[[int, int], Sequence[int]], wait_s: float) -> Vehicle:
    vehicle = Vehicle(policy)
    heard = Heard(-float("inf"))
    vehicle.channel = CommandChannel("vehicle 0 (sysid 1)", 255, vehicle.send, liveness=heard,
                                     silent_wait_s=wait_s)
    vehicle.heard = heard  # type: ignore[attr-defined]
    return vehicle


def test_a_vehicle_silent_since_before_the_command_is_waited_for_then_asked_again(
        caplog: pytest.LogCaptureFixture) -> None:
    # GIVEN a vehicle heard at 0.13 s and silent since (a program compiling), that answers the
    # command once it speaks again 0.4 s later
    async def scenario() -> MavResult:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=5.0)
        vehicle.heard.start()

        def speaks() -> None:
            vehicle.heard.last = vehicle.heard.now_s()
            vehicle.policy = lambda c, n: [MavResult.ACCEPTED]
        asyncio.get_running_loop().call_later(0.4, speaks)
        result = await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.05, retries=2)
        assert [n for _, n, _ in vehicle.sent] == [0, 1, 2, 0]  # a new round once it spoke
        assert vehicle.channel.stats().silent_waits == 1
        return result

    # WHEN a command gets no ACK THEN it waits (and says so), asks again and gets its answer
    assert run(scenario()) == MavResult.ACCEPTED
    assert ("vehicle 0 (sysid 1): MAV_CMD_COMPONENT_ARM_DISARM (400) unanswered: heard at "
            "0.13 s, silent since; waiting up to 5 s for it to speak") in caplog.text


def test_a_vehicle_that_spoke_after_the_command_then_stalled_is_waited_for_then_asked_again(
        caplog: pytest.LogCaptureFixture) -> None:
    # GIVEN a vehicle that sends one more message 0.05 s after the command (in flight when it
    # stalled), then nothing until 2.0 s later, when it speaks and answers
    async def scenario() -> tuple[MavResult, float]:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=5.0)
        vehicle.heard.start()
        loop = asyncio.get_running_loop()

        def last_words() -> None:
            vehicle.heard.last = vehicle.heard.now_s()

        def speaks() -> None:
            vehicle.heard.last = vehicle.heard.now_s()
            vehicle.policy = lambda c, n: [MavResult.ACCEPTED]
        loop.call_later(0.05, last_words)
        loop.call_later(2.0, speaks)
        t0 = loop.time()
        result = await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.05, retries=2)
        assert [n for _, n, _ in vehicle.sent] == [0, 1, 2, 0]
        assert vehicle.channel.stats().silent_waits == 1
        return result, loop.time() - t0

    # WHEN its attempts end 0.1 s into the stall THEN the rest of the silence span is waited
    # out (nothing came), it is called silent, waited for, asked again, and answers
    result, took = run(scenario())
    assert result == MavResult.ACCEPTED and 2.0 <= took < 2.5
    assert ("vehicle 0 (sysid 1): MAV_CMD_COMPONENT_ARM_DISARM (400) unanswered: heard at "
            "2.05 s, silent since; waiting up to 5 s") in caplog.text


def test_a_vehicle_that_keeps_speaking_without_an_answer_is_not_called_silent() -> None:
    # GIVEN a vehicle that spoke after the command and again within the silence span (its
    # HEARTBEAT), never answering
    async def scenario() -> Vehicle:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=30.0)
        vehicle.heard.start()
        loop = asyncio.get_running_loop()
        for at in (0.05, 1.0):
            loop.call_later(at, lambda: setattr(vehicle.heard, "last", vehicle.heard.now_s()))
        with pytest.raises(CommandTimeoutError, match=r"in 3 attempts of 0\.05 s"):
            await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.05, retries=2)
        return vehicle

    # THEN the command fails as unanswered once it speaks, not after a wait for its voice
    assert run(scenario(), timeout_s=3.0).channel.stats().silent_waits == 0


def test_a_vehicle_silent_for_longer_than_the_bound_fails_saying_it_was_silent() -> None:
    async def scenario() -> None:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=0.2)
        vehicle.heard.start()
        await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.03, retries=1)

    with pytest.raises(CommandTimeoutError, match=(
            r"vehicle 0 \(sysid 1\): MAV_CMD_COMPONENT_ARM_DISARM \(400\) got no COMMAND_ACK: "
            r"the vehicle, heard at 0\.13 s, sent nothing at all for 0\.2 s more \(alive "
            r"before, silent since; not a refusal\)")):
        run(scenario())


def test_a_vehicle_that_talks_but_never_acks_fails_after_its_retries_without_waiting() -> None:
    # GIVEN a vehicle whose telemetry keeps arriving (heard "now" at every look) but that never
    # answers the command: that is a refusal to answer, not a silence
    async def scenario() -> Vehicle:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=30.0)
        vehicle.heard.start()
        vehicle.heard.last_heard_s = vehicle.heard.now_s  # type: ignore[method-assign]
        t0 = asyncio.get_running_loop().time()
        with pytest.raises(CommandTimeoutError, match=r"got no COMMAND_ACK in 3 attempts of "
                                                       r"0\.03 s"):
            await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.03, retries=2)
        assert asyncio.get_running_loop().time() - t0 < 5.0  # not the 30 s silence bound
        return vehicle

    vehicle = run(scenario(), timeout_s=10.0)
    assert vehicle.channel.stats().silent_waits == 0


def test_a_vehicle_quiet_for_less_than_a_heartbeat_period_is_not_called_silent() -> None:
    # GIVEN a vehicle last heard 0.5 s ago (a 1 Hz HEARTBEAT is all it sends) that does not
    # answer a command whose attempts take 0.09 s
    async def scenario() -> Vehicle:
        vehicle = silent_vehicle(lambda c, n: [], wait_s=30.0)
        vehicle.heard.start()
        vehicle.heard.last = vehicle.heard.now_s() - 0.5
        with pytest.raises(CommandTimeoutError, match=r"in 3 attempts of 0\.03 s"):
            await vehicle.channel.command_long(ARM, [1.0], timeout_s=0.03, retries=2)
        return vehicle

    # THEN that is an unanswered command, not a silence to wait out
    assert run(scenario(), timeout_s=5.0).channel.stats().silent_waits == 0
