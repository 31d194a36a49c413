"""Setpoint encoders without sockets: frames, clamps, counters; the team batch by its interface."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.codec import MavlinkCodec, MAVLinkMessage
from gcs.link.config import VehicleLinkConfig
from gcs.link.setpoints import TeamSetpoints, VehicleSetpoints
from gcs.link.udp import Address

NAME = "vehicle 1 (sysid 2)"


def decode(data: bytes) -> MAVLinkMessage:
    return mavlink.MAVLink(None).decode(bytearray(data))


class Outbox:
    """What a VehicleSetpoints hands to its link, encoded as the proxy's send path would."""

    def __init__(self, codec: MavlinkCodec) -> None:
        self.codec = codec
        self.sent: list[MAVLinkMessage] = []

    def send(self, msg: MAVLinkMessage) -> bool:
        self.sent.append(decode(self.codec.encode(msg)))
        return True


def sender(codec: MavlinkCodec | None = None) -> tuple[VehicleSetpoints, Outbox]:
    cfg = VehicleLinkConfig(vehicle_id=1, sysid=2, local_port=0, learn_remote=True)
    box = Outbox(codec if codec is not None else MavlinkCodec(cfg.gcs_sysid, cfg.gcs_compid))
    return VehicleSetpoints(NAME, cfg, box.codec, box.send, lambda: 1234), box


def test_rates_go_out_as_frd_and_thrust_is_clamped_and_counted() -> None:
    # GIVEN one vehicle's setpoints
    setpoints, box = sender()
    # WHEN rates in FLU and a thrust above 1 are sent
    setpoints.send_rates_thrust([0.1, 0.2, 0.3], 1.4)
    # THEN the vehicle gets FRD rates, thrust 1, and both the send and the clamp are counted
    (msg,) = box.sent
    assert (msg.get_type(), msg.target_system, msg.type_mask) == ("SET_ATTITUDE_TARGET", 2, 128)
    assert [msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate] == \
        pytest.approx([0.1, -0.2, -0.3])
    assert msg.thrust == 1.0 and msg.time_boot_ms == 1234
    assert setpoints.counts() == {"setpoints_sent": 1, "setpoints_rejected": 0,
                                  "thrust_clamped": 1, "torque_clamped": 0}


def test_position_targets_are_given_in_enu_and_sent_in_the_local_ned_frame() -> None:
    # GIVEN one vehicle's setpoints
    setpoints, box = sender()
    # WHEN an ENU position target with an acceleration feed-forward is sent, yaw 0.5 rad short
    # of north (ENU yaw pi/2 - 0.5)
    setpoints.send_position_target([2.0, 1.0, 3.0], [0.0, 0.1, 0.0], math.pi / 2 - 0.5,
                                   [0.0, 0.0, 0.2])
    # THEN it goes out as NED in MAV_FRAME_LOCAL_NED, yaw from north clockwise, yaw rate ignored
    (msg,) = box.sent
    assert (msg.coordinate_frame, msg.type_mask) == (1, 2048)
    assert [msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.afz, msg.yaw] == \
        pytest.approx([1.0, 2.0, -3.0, 0.1, 0.0, -0.2, 0.5])


class FakePort:
    def __init__(self) -> None:
        self.batches: list[tuple[list[bytes], list[Address | None]]] = []

    def send_many(self, datagrams: list[bytes], addrs: list[Address | None]) -> None:
        self.batches.append((datagrams, addrs))


@dataclass
class Member:
    """A team member with nothing but `TeamMember`'s public interface (no proxy privates)."""

    config: VehicleLinkConfig
    port: FakePort
    remote: Address | None
    codec: MavlinkCodec = field(default_factory=MavlinkCodec)
    tlog: None = None
    no_remote: int = 0

    def __post_init__(self) -> None:
        self.setpoints = VehicleSetpoints(f"vehicle {self.config.sysid}", self.config,
                                          self.codec, lambda _msg: True, lambda: 0)

    def now_s(self) -> float:
        return 10.0

    def up_since_s(self) -> float:
        return 9.0

    def batch_address(self) -> Address | None:
        if self.remote is None:
            self.no_remote += 1
        return self.remote


def test_team_setpoints_use_only_the_members_public_interface() -> None:
    # GIVEN two vehicles on one port, the second's address not known yet
    port = FakePort()
    members = [Member(VehicleLinkConfig(vehicle_id=k + 1, sysid=k + 1, local_port=0, learn_remote=True), port,
                      ("127.0.0.1", 14541) if k == 0 else None) for k in range(2)]
    # WHEN the team's rates go out in one batch, the second thrust above 1
    TeamSetpoints(members).send_rates_thrust([0, 1], np.array([[0.1, 0.2, 0.3], [0.0] * 3]),
                                             np.array([0.5, 1.5]))
    # THEN each vehicle's frame goes to its address in one call, counted on each member
    ((datagrams, addrs),) = port.batches
    assert addrs == [("127.0.0.1", 14541), None]
    first, second = (decode(d) for d in datagrams)
    assert (first.target_system, first.time_boot_ms, first.body_pitch_rate) == \
        (1, 1000, pytest.approx(-0.2))
    assert (second.target_system, second.thrust) == (2, 1.0)
    assert [m.setpoints.counts()["setpoints_sent"] for m in members] == [1, 1]
    assert [m.setpoints.counts()["thrust_clamped"] for m in members] == [0, 1]
    assert [m.no_remote for m in members] == [0, 1]
