"""Telemetry cache, sequence-loss tracking, state snapshots, mode encodings and link config."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.config import VehicleLinkConfig, check_unique_sysids, shared_ports
from gcs.link.enums import (
    LandedState,
    MavAutopilot,
    Px4AutoSubMode,
    Px4MainMode,
    mode_name,
    px4_custom_mode,
    px4_mode_parts,
)
from gcs.link.telemetry import SequenceTracker, TelemetryCache, build_state

MAV = mavlink.MAVLink(None, 1, 1)


def track(seqs: list[int]) -> SequenceTracker:
    tracker = SequenceTracker()
    for s in seqs:
        tracker.update(s)
    return tracker


# --- sequence numbers ----------------------------------------------------------------------------


def test_contiguous_sequence_with_wraparound_has_no_loss() -> None:
    stats = track([253, 254, 255, 0, 1, 2]).stats()
    assert (stats.received, stats.lost, stats.loss_fraction) == (6, 0, 0.0)


def test_gaps_count_the_missing_packets_also_across_the_wrap() -> None:
    # GIVEN 10, 11, (12, 13 missing) 14, (105 missing) 120, (119 missing) 240, (17 missing) 2
    stats = track([10, 11, 14, 120, 240, 2]).stats()
    # THEN every forward jump below 128 counts its missing packets
    assert stats.lost == 2 + 105 + 119 + 17
    assert stats.loss_fraction == pytest.approx(243 / (243 + 6))


def test_a_jump_of_128_or_more_is_read_as_a_late_packet() -> None:
    # An 8-bit sequence cannot tell 128+ lost packets from one late packet: the latter is assumed.
    stats = track([10, 200, 11]).stats()
    assert (stats.lost, stats.reordered) == (0, 1)


def test_duplicates_and_reordering_are_not_loss() -> None:
    # 6 comes after 7: the gap it left is filled, so nothing was lost
    stats = track([5, 5, 7, 6, 8]).stats()
    assert (stats.duplicates, stats.reordered, stats.lost) == (1, 1, 0)
    # 9 never comes: one lost, whatever arrived late around it
    stats = track([5, 7, 6, 10, 8, 11]).stats()
    assert (stats.reordered, stats.lost) == (2, 1)


# --- cache and state ---------------------------------------------------------------------------


def test_cache_keeps_the_latest_and_estimates_rate() -> None:
    cache = TelemetryCache()
    for k in range(50):
        cache.update(MAV.local_position_ned_encode(k, float(k), 0, 0, 0, 0, 0), 10.0 + 0.01 * k)
    latest = cache.latest("LOCAL_POSITION_NED")
    assert latest is not None and latest.msg.x == 49.0 and latest.rx_time_s == pytest.approx(10.49)
    stats = cache.type_stats()["LOCAL_POSITION_NED"]
    assert stats.count == 50 and stats.rate_hz == pytest.approx(100.0)
    assert cache.latest("ATTITUDE") is None


def test_a_silence_moves_the_rate_little_and_a_slower_stream_is_followed() -> None:
    # GIVEN a 5 Hz stream, then 4 s of silence (its vehicle program stopped), then 5 Hz again
    cache = TelemetryCache()
    times = [0.2 * k for k in range(20)] + [3.8 + 4.0 + 0.2 * k for k in range(1, 4)]
    for t in times:
        cache.update(MAV.extended_sys_state_encode(0, 1), t)
    # THEN three intervals after it the rate is within 20 % of the stream's (an interval of 4 s
    # taken at face value leaves 1.7 Hz: a ready check would read a 5 Hz stream as broken)
    assert cache.rate_hz("EXTENDED_SYS_STATE") == pytest.approx(5.0, rel=0.2)
    # AND a stream that really slowed to 1 Hz is read as 1 Hz within 20 of its intervals
    for k in range(1, 21):
        cache.update(MAV.extended_sys_state_encode(0, 1), 8.4 + k)
    assert cache.rate_hz("EXTENDED_SYS_STATE") == pytest.approx(1.0, rel=0.2)


def test_state_before_any_telemetry_is_nan_with_infinite_age() -> None:
    state = build_state(TelemetryCache(), sysid=3, now_s=5.0)
    assert np.all(np.isnan(state.position_enu_m)) and np.all(np.isnan(state.rotation_enu_flu))
    assert state.position_age_s == math.inf and state.heartbeat_age_s == math.inf
    assert (state.armed, state.mode, state.landed_state) == (False, "", LandedState.UNDEFINED)


def test_state_converts_every_source_to_enu_flu_with_receive_times() -> None:
    # GIVEN a vehicle 2 m north, 1 m east, 3 m up, climbing, yawed to face east, rolling right
    cache = TelemetryCache()
    s = math.sqrt(0.5)
    cache.update(MAV.local_position_ned_encode(0, 2.0, 1.0, -3.0, 0.5, 0.0, -1.0), 1.0)
    cache.update(MAV.attitude_quaternion_encode(0, s, 0.0, 0.0, s, 0.1, 0.2, 0.3), 1.1)
    cache.update(MAV.highres_imu_encode(0, 0.0, 0.0, -9.81, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0), 1.2)
    offboard = px4_custom_mode(Px4MainMode.OFFBOARD)
    cache.update(MAV.heartbeat_encode(2, MavAutopilot.PX4, 129, offboard, 4), 1.3)
    cache.update(MAV.extended_sys_state_encode(0, LandedState.IN_AIR), 1.4)
    # WHEN a snapshot is taken at t = 2 s
    state = build_state(cache, sysid=1, now_s=2.0)
    # THEN values are in ENU/FLU
    np.testing.assert_allclose(state.position_enu_m, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(state.velocity_enu_mps, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(state.rotation_enu_flu, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(state.omega_flu_radps, [0.1, -0.2, -0.3])
    np.testing.assert_allclose(state.specific_force_flu_mps2, [0.0, 0.0, 9.81], rtol=1e-6)
    assert state.armed and state.mode == "OFFBOARD" and state.custom_mode == 393216
    assert state.landed_state == LandedState.IN_AIR
    # AND each group has its own age
    assert state.position_age_s == pytest.approx(1.0)
    assert state.attitude_age_s == pytest.approx(0.9)
    assert state.imu_age_s == pytest.approx(0.8)
    assert state.heartbeat_age_s == pytest.approx(0.7)
    assert state.landed_state_age_s == pytest.approx(0.6)
    # AND the arrays are read-only
    with pytest.raises(ValueError):
        state.position_enu_m[0] = 0.0


def test_state_uses_the_newer_of_attitude_and_attitude_quaternion() -> None:
    cache = TelemetryCache()
    cache.update(MAV.attitude_quaternion_encode(0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 1.0)
    cache.update(MAV.attitude_encode(0, 0.0, 0.0, math.pi / 2, 0.0, 0.0, 0.5), 1.5)
    state = build_state(cache, sysid=1, now_s=2.0)
    np.testing.assert_allclose(state.rotation_enu_flu, np.eye(3), atol=1e-12)  # facing east
    np.testing.assert_allclose(state.omega_flu_radps, [0.0, 0.0, -0.5])
    assert state.attitude_rx_s == 1.5


# --- modes -------------------------------------------------------------------------------------


def test_px4_custom_mode_encoding() -> None:
    assert px4_custom_mode(Px4MainMode.OFFBOARD) == 393216
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    assert px4_mode_parts(land) == (4, 6)
    assert mode_name(MavAutopilot.PX4, land) == "AUTO_LAND"
    assert mode_name(MavAutopilot.PX4, px4_custom_mode(Px4MainMode.POSCTL)) == "POSCTL"
    assert mode_name(MavAutopilot.PX4, 99 << 16) == f"CUSTOM({99 << 16})"
    assert mode_name(MavAutopilot.ARDUPILOTMEGA, 4) == "GUIDED"
    assert mode_name(MavAutopilot.ARDUPILOTMEGA, 20) == "GUIDED_NOGPS"


# --- config ------------------------------------------------------------------------------------


def test_px4_sitl_defaults() -> None:
    cfg = VehicleLinkConfig.px4_sitl(2)
    assert (cfg.sysid, cfg.local_port, cfg.remote) == (3, 14542, ("127.0.0.1", 14582))
    assert cfg.name == "vehicle 3 (sysid 3)"
    assert VehicleLinkConfig.px4_sitl(0, link_timeout_s=0.2).link_timeout_s == 0.2
    with pytest.raises(ValueError, match="PX4 SITL instance 10: instances above 9 all send"):
        VehicleLinkConfig.px4_sitl(10)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"sysid": 0}, r"vehicle 1 link: sysid: expected 1\.\.255, got 0"),
        ({"sysid": 255}, r"vehicle 1 link: sysid: 255 equals the GCS sysid 255"),
        ({"remote_port": None}, r"vehicle 1 link: remote_port: missing"),
        ({"link_timeout_s": 0.0}, r"vehicle 1 link: link_timeout_s: expected > 0, got 0\.0"),
        ({"signing_key": b"short"}, r"vehicle 1 link: signing_key: expected 32 bytes, got 5"),
    ],
)
def test_config_errors_name_the_key(kwargs: dict[str, object], message: str) -> None:
    base: dict[str, object] = {"vehicle_id": 1, "sysid": 2, "local_port": 0, "remote_port": 14581}
    with pytest.raises(ValueError, match=message):
        VehicleLinkConfig(**(base | kwargs))  # type: ignore[arg-type]


def test_duplicate_sysids_are_rejected_and_shared_ports_found() -> None:
    a = VehicleLinkConfig.px4_sitl(0)
    b = VehicleLinkConfig.px4_sitl(1, sysid=1)
    c = VehicleLinkConfig.px4_sitl(2, local_port=14540)
    free = VehicleLinkConfig.px4_sitl(3, local_port=0)
    check_unique_sysids([a, VehicleLinkConfig.px4_sitl(1)])
    with pytest.raises(ValueError, match=r"sysid 1 used by vehicles \[1, 2\]"):
        check_unique_sysids([a, b])
    # a shared GCS port is allowed (told apart by sysid); port 0 is never shared
    check_unique_sysids([a, c])
    assert shared_ports([a, c, free, VehicleLinkConfig.px4_sitl(4, local_port=0)]) == {
        ("127.0.0.1", 14540): [1, 3]}
