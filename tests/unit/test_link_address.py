"""A vehicle's address (VehicleAddress): learned from its first message only with learn_remote,
strangers counted and logged once each up to a bound, a foreign vehicle's HEARTBEAT reported."""

from __future__ import annotations

import logging

import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.address import MAX_STRANGERS_LOGGED, VehicleAddress
from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import MavAutopilot, MavState, MavType
from gcs.link.udp import Address

NAME = "vehicle 1 (sysid 2)"
FIRST: Address = ("127.0.0.1", 40001)
OTHER: Address = ("127.0.0.1", 40002)


def heartbeat(sysid: int, mav_type: int = MavType.QUADROTOR) -> MAVLinkMessage:
    """A HEARTBEAT as received: packed by ``sysid`` and decoded again."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
    data = mav.heartbeat_encode(mav_type, MavAutopilot.PX4, 0, 0, MavState.ACTIVE).pack(mav)
    return mavlink.MAVLink(None).decode(bytearray(data))


def test_the_first_address_is_learned_with_learn_remote_and_a_stranger_is_counted(
        caplog: pytest.LogCaptureFixture) -> None:
    learned: list[Address] = []
    address = VehicleAddress(NAME, 2, None, learn_remote=True, on_learn=learned.append)
    # GIVEN no address yet, WHEN the vehicle's first message comes from FIRST
    with caplog.at_level(logging.INFO, logger="gcs.link.proxy"):
        assert address.accepts(FIRST)
    # THEN FIRST is its address, said once to the callback and the proxy's log
    assert address.remote == FIRST and address.learned and learned == [FIRST]
    assert f"{NAME}: address learned from its first message: 127.0.0.1:40001" in caplog.text
    # AND its next messages from FIRST are accepted, one from OTHER is not, and is counted
    assert address.accepts(FIRST)
    assert not address.accepts(OTHER)
    assert learned == [FIRST] and address.remote == FIRST
    assert address.counts() == {"foreign_sysid": 0, "stranger_address": 1}
    assert ("messages with its sysid 2 from 127.0.0.1:40002, but its address is "
            "127.0.0.1:40001") in caplog.text


def test_a_fixed_remote_accepts_any_address_and_learns_none() -> None:
    learned: list[Address] = []
    address = VehicleAddress(NAME, 2, FIRST, learn_remote=False, on_learn=learned.append)
    # WHEN the vehicle's messages come from another address than the configured one
    assert address.accepts(OTHER) and address.accepts(FIRST) and address.accepts(OTHER)
    # THEN they are all accepted, and the address stays the configured one
    assert address.remote == FIRST and not address.learned and learned == []
    assert address.counts()["stranger_address"] == 0


def test_every_stranger_is_counted_but_only_the_first_few_addresses_logged(
        caplog: pytest.LogCaptureFixture) -> None:
    address = VehicleAddress(NAME, 2, None, learn_remote=True)
    address.accepts(FIRST)
    strangers = [("10.0.0.1", 50000 + k) for k in range(MAX_STRANGERS_LOGGED + 3)]
    # WHEN messages come from more stranger addresses than are logged, each twice
    with caplog.at_level(logging.WARNING, logger="gcs.link.proxy"):
        for addr in strangers + strangers:
            assert not address.accepts(addr)
    # THEN each is counted, and one line is logged per address up to the bound
    assert address.counts()["stranger_address"] == 2 * len(strangers)
    assert len(caplog.records) == MAX_STRANGERS_LOGGED
    assert all(r.name == "gcs.link.proxy" for r in caplog.records)


def test_a_foreign_vehicle_heartbeat_is_a_mismatch_and_a_ground_stations_is_not(
        caplog: pytest.LogCaptureFixture) -> None:
    address = VehicleAddress(NAME, 2, FIRST, learn_remote=False)
    # WHEN another ground station's HEARTBEAT arrives
    address.foreign(heartbeat(255, MavType.GCS), OTHER)
    # THEN it is counted as foreign, not reported
    assert address.mismatch is None and address.counts()["foreign_sysid"] == 1
    # WHEN a vehicle with sysid 7 beats twice
    with caplog.at_level(logging.ERROR, logger="gcs.link.proxy"):
        address.foreign(heartbeat(7), OTHER)
        address.foreign(heartbeat(7), OTHER)
    # THEN it is the mismatch, logged once, naming both sysids and the address
    assert address.mismatch == 7 and address.counts()["foreign_sysid"] == 3
    assert len(caplog.records) == 1
    assert caplog.records[0].getMessage() == (
        f"{NAME}: HEARTBEAT from sysid 7 (compid 1) at 127.0.0.1:40002, expected sysid 2; check "
        "the team file. Messages from sysid 7 are ignored.")
