"""The vehicle-clock filter: true sample times from stamps under drift, jitter, spikes, reboots."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.link.clock import BUNCHED, LinkRoundTrips, VehicleClock

RATE_HZ = 50.0


def stream(clock: VehicleClock, seconds: float, *, rate_hz: float = RATE_HZ, offset_s: float = 7.0,
           vehicle_rate: float = 1.0, delay_s=lambda t: 0.002, t0_s: float = 0.0,
           stamp_ms: bool = True) -> list[tuple[float, float, float]]:
    """Feed samples taken every 1/rate_hz s of ground-station time; returns (t_true, t_vehicle,
    rx) per sample. The vehicle clock runs at ``vehicle_rate`` x ours, from ``offset_s`` back."""
    out = []
    for k in range(int(seconds * rate_hz)):
        t_true = t0_s + k / rate_hz
        t_vehicle = (t_true - offset_s) * vehicle_rate
        if stamp_ms:
            t_vehicle = np.floor(t_vehicle * 1e3) / 1e3
        rx = t_true + delay_s(t_true)
        clock.on_sample(t_vehicle, rx)
        out.append((t_true, t_vehicle, rx))
    return out


def test_true_sample_time_under_the_recorded_sitl_drift():
    # PX4 SITL's clock ran 1.2 % slow (data/sitl timing.json: 12090 ppm)
    clock = VehicleClock()
    rng = np.random.default_rng(1)
    samples = stream(clock, 30.0, vehicle_rate=1 - 0.01209,
                     delay_s=lambda t: 0.001 + rng.exponential(0.002))
    for t_true, t_vehicle, rx in samples[-100:]:
        # 1 ms stamps and the 1 ms least delay (no TIMESYNC here) bound the error
        assert abs(clock.sample_time_s(t_vehicle, rx) - t_true) < 2.5e-3
    assert clock.estimate().drift_ppm == pytest.approx(1e6 * 0.01209 / (1 - 0.01209), rel=0.02)


def test_a_delay_spike_shows_as_age_and_does_not_move_the_envelope():
    clock = VehicleClock()
    spike = lambda t: 0.002 + (0.5 if 20.0 <= t < 22.0 else 0.0)  # noqa: E731
    samples = stream(clock, 30.0, delay_s=spike)
    during = [s for s in samples if 21.0 <= s[0] < 22.0]
    for _t_true, t_vehicle, rx in during:
        age_at_rx = rx - clock.sample_time_s(t_vehicle, rx)
        assert age_at_rx == pytest.approx(0.5, abs=5e-3)
    after = samples[-10:]
    for t_true, t_vehicle, rx in after:
        assert abs(clock.sample_time_s(t_vehicle, rx) - t_true) < 3.5e-3


def test_timesync_round_trip_gives_the_least_one_way_delay():
    clock = VehicleClock()
    samples = stream(clock, 10.0, delay_s=lambda t: 0.050)
    # without round trips the 50 ms transport is invisible: the age is a lower bound
    t_true, t_vehicle, rx = samples[-1]
    assert rx - clock.sample_time_s(t_vehicle, rx) < 2e-3
    for rtt in (0.104, 0.101, 0.100, 0.130):
        clock.on_round_trip(rtt)
    assert clock.least_delay_s == pytest.approx(0.050)
    assert clock.sample_time_s(t_vehicle, rx) == pytest.approx(t_true, abs=1.5e-3)
    assert list(clock.round_trips_s()) == [0.104, 0.101, 0.100, 0.130]


def test_a_lasting_rise_of_the_delay_restarts_the_least_round_trip_at_its_third_reply():
    # GIVEN a loopback link (1 ms round trips, 20 ms jitter apart at most) for 20 replies
    clock = VehicleClock()
    for k in range(20):
        clock.on_round_trip(0.001 + 0.019 * (k % 2))
    assert clock.least_delay_s == pytest.approx(0.0005)
    # WHEN 50 ms each way join it for good (a link changed, a fault starts): the old least round
    # trip would stand for 20 replies, with the envelope lifted ages would read 50 ms low
    for rtt in (0.101, 0.112):
        clock.on_round_trip(rtt)
        assert clock.least_delay_s == pytest.approx(0.0005)  # two slow replies may be jitter
    clock.on_round_trip(0.105)
    # THEN the third slow reply in a row restarts it: half the least of the three
    assert clock.least_delay_s == pytest.approx(0.0505)
    assert clock.delay_rises == 1
    assert list(clock.round_trips_s()) == [0.101, 0.112, 0.105]
    assert clock.estimate().rtt_samples == 23
    # AND jitter within the rise's margin above the new least one restarts nothing
    for k in range(30):
        clock.on_round_trip(0.100 + 0.019 * (k % 3 != 0))
    assert clock.least_delay_s == pytest.approx(0.050)
    assert clock.delay_rises == 1


@pytest.mark.parametrize("down_share", [0.5, 1.0, 0.0])
def test_ages_stay_true_through_a_lasting_rise_of_the_delay(down_share):
    # GIVEN 30 s of a 2 ms link each way (samples at 50 Hz, a TIMESYNC every 0.5 s), then 100 ms
    # more on the round trip for good: both ways alike, all of it on the downlink (telemetry),
    # or all on the uplink
    clock = VehicleClock()
    offset, errors = 7.0, []
    for k in range(int(60.0 * RATE_HZ)):
        t_true = k / RATE_HZ
        rose = t_true >= 30.0
        down = 0.002 + (0.100 * down_share if rose else 0.0)
        rx = t_true + down
        clock.on_sample(t_true - offset, rx)
        if k % int(RATE_HZ / 2) == 0:
            clock.on_round_trip(0.004 + (0.100 if rose else 0.0))
        if t_true >= 31.5:  # from the third slow reply on
            errors.append(clock.sample_time_s(t_true - offset, rx) - t_true)
    errors = np.array(errors)
    assert clock.delay_rises == 1
    if down_share == 0.5:
        # THEN with the rise alike both ways, every sample's time stays within 2 ms of the truth
        assert np.abs(errors).max() < 2e-3
    elif down_share == 1.0:
        # the least delay takes half the round trip each way: once the envelope has the whole
        # downlink rise, ages read low by the other half (the steady state of any clock that
        # splits a round trip evenly), the envelope's fit overshooting it by up to 10 ms
        assert errors.min() > -2e-3 and errors.max() < 0.050 + 10e-3
        assert abs(errors[-1] - 0.050) < 1e-3
    else:
        # an uplink-only rise: the telemetry comes as early as before, so ages never read low,
        # and high by the round trip's rise at most (+ 10 ms of the fit's), then by half of it
        assert errors.max() < 2e-3 and errors.min() > -0.100 - 10e-3
        assert abs(errors[-1] + 0.050) < 1e-3


def test_slow_replies_that_measured_a_stop_are_no_lasting_rise():
    # a stop held the last three replies (bunched: the link's record leaves them out)
    clock = VehicleClock()
    for _ in range(10):
        clock.on_round_trip(0.010)
    for _ in range(3):
        clock.on_round_trip(0.900, of_link=False)
    assert clock.least_delay_s == pytest.approx(0.005)
    assert clock.delay_rises == 0


def test_the_recent_round_trip_is_the_median_of_the_latest_three():
    # GIVEN a link whose round trips take 10-12 ms
    clock = VehicleClock()
    assert math.isnan(clock.recent_round_trip_s)
    for rtt in (0.010, 0.012, 0.011):
        clock.on_round_trip(rtt)
    assert clock.recent_round_trip_s == 0.011
    # WHEN one reply is held up 0.43 s THEN the recent round trip stays with the others
    clock.on_round_trip(0.430)
    assert clock.recent_round_trip_s == 0.012
    clock.on_round_trip(0.011)
    assert clock.recent_round_trip_s == 0.011
    # WHEN the link's delay lasts THEN the second late reply is the recent round trip
    clock.on_round_trip(0.650)
    clock.on_round_trip(0.640)
    assert clock.recent_round_trip_s == 0.640
    assert clock.last_round_trip_s == 0.640


def test_round_trips_can_be_read_from_a_time_on_those_sent_since():
    # the preflight judges the link delay from the round trips since the team was configured:
    # not those the ground station's own start-up load lifted
    clock = VehicleClock()
    for k, rtt in enumerate((0.400, 0.250, 0.012, 0.010, 0.011)):
        clock.on_round_trip(rtt, sent_s=0.5 * k)
    assert list(clock.round_trips_s(1.0)) == [0.012, 0.010, 0.011]
    assert list(clock.round_trips_s(5.0)) == []
    assert list(clock.round_trips_s()) == [0.400, 0.250, 0.012, 0.010, 0.011]
    clock.on_round_trip(0.013)  # sent when, unknown: only read without a start
    assert list(clock.round_trips_s(1.0)) == [0.012, 0.010, 0.011]
    for k in range(30):  # the ring wraps: the times stay with their round trips
        clock.on_round_trip(0.001 * k, sent_s=10.0 + k)
    assert list(clock.round_trips_s(37.0)) == [0.027, 0.028, 0.029]


def test_a_sample_is_never_taken_after_it_arrived():
    clock = VehicleClock()
    stream(clock, 5.0, delay_s=lambda t: 0.010)
    for rtt in (0.2, 0.2):  # a round trip far longer than the telemetry's own delay
        clock.on_round_trip(rtt)
    assert clock.sample_time_s(10.0, 17.01) <= 17.01


def test_a_reboot_restarts_the_filter():
    clock = VehicleClock()
    stream(clock, 10.0, offset_s=-100.0)
    # the vehicle rebooted: its clock restarts at 0 while ours goes on
    samples = stream(clock, 5.0, offset_s=17.5, t0_s=17.5)
    assert clock.estimate().resets == 1
    t_true, t_vehicle, rx = samples[-1]
    assert abs(clock.sample_time_s(t_vehicle, rx) - t_true) < 3e-3


def test_before_any_sample_and_for_bad_stamps_the_receive_time_stands():
    clock = VehicleClock()
    assert clock.sample_time_s(1.0, 5.0) == 5.0
    clock.on_sample(float("nan"), 5.0)
    clock.on_sample(-1.0, 5.0)
    assert not clock.synced
    stream(clock, 3.0)
    assert clock.sample_time_s(float("nan"), 9.0) == 9.0
    clock.on_round_trip(float("nan"))
    clock.on_round_trip(-0.1)
    assert clock.estimate().rtt_samples == 0


def test_a_bound_line_always_holds_what_sample_time_uses():
    # GIVEN a clock writing its line into a team array's row, fed through every kind of change:
    # the first samples, bin closes and fits, a delay spike, round trips, a reboot
    team = np.full((3, 4), np.nan)
    clock = VehicleClock()
    clock.bind_line(team[1])
    rng = np.random.default_rng(7)
    t_vehicle = 0.0
    for k in range(3000):
        t_vehicle += 0.01
        if k == 1500:
            t_vehicle = 0.5  # reboot
        delay = 0.004 + 0.002 * rng.random() + (0.05 if 700 < k < 720 else 0.0)
        clock.on_sample(t_vehicle, 100.0 + 1.0001 * t_vehicle + delay)
        if k % 50 == 0:
            clock.on_round_trip(0.006 + 0.002 * rng.random())
        # THEN the row mapped by hand gives the filter's own sample time, at every step
        a, b, t_ref, least = team[1]
        rx = 100.0 + 1.0001 * t_vehicle + 0.01
        by_row = rx if a != a else min(rx, t_vehicle + a + b * (t_vehicle - t_ref) - least)
        assert by_row == pytest.approx(clock.sample_time_s(t_vehicle, rx), abs=1e-12)
    assert clock.resets == 1
    assert np.isnan(team[[0, 2]]).all()  # the other rows untouched


def test_a_round_trip_that_measured_a_stop_leaves_the_links_record_but_bounds_the_offset():
    # GIVEN a link's round trips of ~10 ms, then two replies held by a stopped vehicle
    clock = VehicleClock()
    for k, rtt in enumerate((0.010, 0.011, 0.012)):
        clock.on_round_trip(rtt, float(k))
    clock.on_round_trip(3.8, 3.0)  # released first: it looks like any reply when it arrives
    clock.disown_last_round_trip()  # the next reply came bunched with it
    clock.on_round_trip(3.3, 3.5, of_link=False)
    # THEN the link's round trips are the three of the link alone, with or without a start
    assert list(clock.round_trips_s()) == [0.010, 0.011, 0.012]
    assert list(clock.round_trips_s(1.0)) == [0.011, 0.012]
    assert list(clock.round_trips_s(3.0)) == []
    # AND the recent round trip (the uplink delay rule's) is the link's too
    assert clock.recent_round_trip_s == 0.011


def test_replies_that_come_bunched_leave_the_links_round_trips_both_of_them():
    clock = VehicleClock()
    trips = LinkRoundTrips(clock)
    # GIVEN three replies of a link of 4 ms round trips, requests 0.5 s apart
    for k in range(3):
        trips.on_reply(10.0 + 0.5 * k, 10.004 + 0.5 * k)
    # WHEN the next two requests' replies arrive 2 ms apart, well under BUNCHED of their spacing
    trips.on_reply(11.5, 13.000)
    trips.on_reply(12.0, 13.002)
    assert BUNCHED * 0.5 > 0.002
    # AND the link answers as before
    trips.on_reply(13.5, 13.505)
    # THEN both bunched round trips are out of the record and the clock's, and counted
    assert list(trips.round_trips_s()) == pytest.approx([0.004] * 3 + [0.005])
    assert list(clock.round_trips_s()) == pytest.approx([0.004] * 3 + [0.005])
    assert trips.counts() == {"timesync_replies": 6, "timesync_bunched": 2}
    # AND the clock still saw every reply (a held one bounds the offset all the same)
    assert clock.estimate().rtt_samples == 6


def test_replies_spaced_like_their_requests_are_kept_and_one_before_its_request_is_ignored():
    trips = LinkRoundTrips(VehicleClock())
    # GIVEN replies whose arrivals are spaced as their requests, with a varying delay
    for k, rtt_s in enumerate([0.004, 0.030, 0.006]):
        trips.on_reply(20.0 + 0.5 * k, 20.0 + 0.5 * k + rtt_s)
    # WHEN a reply claims to arrive before its request went out
    trips.on_reply(22.0, 21.9)
    # THEN the three are the link's, none bunched, and the impossible one is not counted
    assert list(trips.round_trips_s()) == pytest.approx([0.004, 0.030, 0.006])
    assert trips.counts() == {"timesync_replies": 3, "timesync_bunched": 0}
