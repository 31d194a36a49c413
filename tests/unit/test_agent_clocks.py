"""A peer's clock offset from four timestamps (gcs/agent/clocks.py): closed forms, the
median of the faster half over its window, the error bound, refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.agent.clocks import OffsetEstimator


def exchange(est: OffsetEstimator, t1: float, offset: float, up: float, held: float,
             down: float) -> bool:
    """One exchange started at our t1 with a peer whose clock reads ours + offset: `up` and
    `down` the two legs' transit times, `held` the time the peer kept it."""
    t2 = t1 + up + offset
    t3 = t2 + held
    t4 = t3 - offset + down
    return est.add(t1, t2, t3, t4)


def test_symmetric_legs_give_the_offset_exactly():
    # GIVEN a peer 5 s ahead, 1 ms each way, held 20 ms
    est = OffsetEstimator()
    assert est.offset_s is None and est.uncertainty_s is None and est.samples == 0
    assert exchange(est, 100.0, 5.0, 0.001, 0.020, 0.001)
    # THEN the offset is 5 s and the round trip 2 ms (the hold excluded)
    assert est.offset_s == pytest.approx(5.0, abs=1e-9)
    assert est.rtt_s == pytest.approx(0.002, abs=1e-9)
    assert est.uncertainty_s == pytest.approx(0.001, abs=1e-9)
    assert est.to_local(105.5) == pytest.approx(100.5, abs=1e-9)
    assert (est.samples, est.total, est.refused) == (1, 1, 0)


def test_asymmetric_legs_err_by_half_their_difference():
    # GIVEN 9 ms up and 1 ms down THEN the offset is off by (9 - 1) / 2 = 4 ms, within rtt / 2
    est = OffsetEstimator()
    exchange(est, 0.0, -2.0, 0.009, 0.0, 0.001)
    assert est.offset_s == pytest.approx(-2.0 + 0.004, abs=1e-9)
    assert abs(est.offset_s - -2.0) <= est.uncertainty_s + 1e-12


def test_the_estimate_is_the_median_offset_of_the_faster_half_within_every_bound():
    # GIVEN exchanges with round trips 10, 2, 6 and 4 ms, each asymmetric its own way
    est = OffsetEstimator(window=4)
    exchange(est, 0.0, 1.0, 0.008, 0.0, 0.002)  # offset +3 ms off
    exchange(est, 1.0, 1.0, 0.0015, 0.0, 0.0005)  # +0.5 ms
    exchange(est, 2.0, 1.0, 0.001, 0.0, 0.005)  # -2 ms
    exchange(est, 3.0, 1.0, 0.0025, 0.0, 0.0015)  # +0.5 ms
    # THEN the faster half (2 and 4 ms) gives +0.5 ms, inside what every exchange allows:
    # [1 + 0.0005 - 0.001, 1 + 0.0005 + 0.001] and the others contain it; the bound is the
    # estimate's distance to the far end of that intersection
    assert est.rtt_s == pytest.approx(0.002) and est.offset_s == pytest.approx(1.0005)
    assert est.uncertainty_s == pytest.approx(0.001)
    # WHEN four more exchanges, all with the least-round-trip one far off, fill the window
    for t1, up, down in ((4.0, 0.0001, 0.0049), (5.0, 0.003, 0.003), (6.0, 0.0035, 0.0035),
                         (7.0, 0.004, 0.004)):
        exchange(est, t1, 1.0, up, 0.0, down)
    # THEN the median of the faster half (5 and 6 ms: -2.4 and 0 ms) is taken, not the least
    # round trip's -2.4 ms
    assert est.samples == 4 and est.rtt_s == pytest.approx(0.005)
    assert est.offset_s == pytest.approx(1.0 - 0.0012)


def test_independent_jitter_on_both_legs_averages_out():
    # GIVEN 512 exchanges whose legs each take 20 ms +- 5 ms (normal, independent), a peer
    # 7 s ahead: the legs' difference does not shrink with their sum, so the least round
    # trip errs by about 5 / sqrt(2) ms
    rng = np.random.default_rng(3)
    est = OffsetEstimator()
    legs = rng.normal(0.020, 0.005, size=(512, 2)).clip(0.0)
    for k, (up, down) in enumerate(legs):
        exchange(est, 100.0 + 0.02 * k, 7.0, up, 0.01, down)
    least = legs[np.argmin(legs.sum(axis=1))]
    # THEN the estimate is within 0.5 ms, where the least round trip alone errs by more
    assert abs(est.offset_s - 7.0) <= 0.0005
    assert abs((least[0] - least[1]) / 2.0) > 0.0005
    assert abs(est.offset_s - 7.0) <= est.uncertainty_s


def test_one_leg_queueing_is_kept_out_by_the_faster_half():
    # GIVEN 1 ms each way plus queueing on the way out only (exponential, mean 10 ms)
    rng = np.random.default_rng(4)
    est = OffsetEstimator()
    for k, queue in enumerate(rng.exponential(0.010, size=512)):
        exchange(est, 10.0 + 0.02 * k, -3.0, 0.001 + queue, 0.0, 0.001)
    # THEN the estimate errs by far less than the median queueing / 2 (3.5 ms)
    assert abs(est.offset_s - -3.0) <= 0.002


def test_exchanges_older_than_max_age_leave_the_window():
    est = OffsetEstimator(window=100, max_age_s=10.0)
    exchange(est, 0.0, 0.0, 0.0001, 0.0, 0.0001)  # the best, at t4 ~ 0
    exchange(est, 5.0, 0.0, 0.002, 0.0, 0.002)
    assert est.rtt_s == pytest.approx(0.0002) and est.samples == 2
    # WHEN one arrives more than 10 s after the best THEN the best is forgotten
    exchange(est, 10.5, 0.0, 0.003, 0.0, 0.003)
    assert est.samples == 2 and est.rtt_s == pytest.approx(0.004)
    assert est.offset_s == pytest.approx(0.0, abs=1e-12)


def test_impossible_exchanges_are_refused_and_counted():
    est = OffsetEstimator()
    # a hold longer than the whole exchange: a negative round trip
    assert not est.add(0.0, 10.0, 10.5, 0.1)
    assert not est.add(0.0, math.nan, 1.0, 2.0)
    assert not est.add(0.0, 1.0, math.inf, 2.0)
    assert (est.refused, est.total, est.offset_s) == (3, 0, None)
    with pytest.raises(LookupError, match="no clock offset measured yet"):
        est.to_local(1.0)


def test_reset_forgets_the_peer():
    est = OffsetEstimator()
    exchange(est, 0.0, 3.0, 0.001, 0.0, 0.001)
    est.reset()
    assert (est.offset_s, est.samples, est.total) == (None, 0, 0)


@pytest.mark.parametrize(("window", "max_age_s"), [(0, 1.0), (4, 0.0)])
def test_a_bad_window_is_refused(window, max_age_s):
    with pytest.raises(ValueError, match="window"):
        OffsetEstimator(window, max_age_s)


legs = st.floats(0.0, 0.05)


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e6, 1e6), st.lists(st.tuples(legs, st.floats(0.0, 1.0), legs), min_size=1,
                                      max_size=40))
def test_the_offset_error_is_within_the_uncertainty(offset, exchanges):
    # GIVEN any offset and any legs and holds THEN |estimate - offset| <= the bound <= rtt_min
    est = OffsetEstimator(window=16)
    t1 = 1000.0
    for up, held, down in exchanges:
        assert exchange(est, t1, offset, up, held, down)
        t1 += 0.02 + held
    tolerance = 1e-9 * max(1.0, abs(offset)) + 1e-9
    assert abs(est.offset_s - offset) <= est.uncertainty_s + tolerance
    assert est.uncertainty_s <= est.rtt_s + tolerance
    assert est.rtt_s == pytest.approx(min(u + d for u, _, d in exchanges[-16:]), abs=tolerance)


def one_leg_jitter_estimate(seed: int) -> OffsetEstimator:
    """An agent's estimate of the supervisor's clock (as tests/agents_across.py flies it): its
    samples go up through 20 ms +- 5 ms (normal), the heartbeats come down in 0.3 ms; one
    exchange every 0.1 s for 25 s; the supervisor's clock is ours."""
    rng = np.random.default_rng(seed)
    est = OffsetEstimator()
    for k, up in enumerate(rng.normal(0.020, 0.005, size=250).clip(0.0)):
        exchange(est, 0.1 * k, 0.0, up, 0.05, 0.0003)
    return est


def test_the_median_offset_is_what_peers_on_alike_paths_agree_on():
    # GIVEN twenty agents, each on its own draw of the same one-leg jitter to one supervisor
    ests = [one_leg_jitter_estimate(seed) for seed in range(20)]
    bounded = np.array([e.offset_s for e in ests])
    median = np.array([e.median_offset_s for e in ests])
    # THEN a bounded estimate that the interval holds back sits at its edge, the least uplink
    # of its window (an extreme: a spread of milliseconds), while the medians, biased alike by
    # half the one leg's faster-half delay, agree within a fraction of a millisecond: the
    # instant the agents convert by the median is one instant for all of them
    assert np.ptp(bounded) > 0.003
    assert np.ptp(median) < 0.001
    assert np.all(median >= bounded) and np.sum(median > bounded) >= 10
    # AND the bound still holds the true offset (0) for the bounded estimate alone
    assert all(abs(e.offset_s) <= e.uncertainty_s + 1e-12 for e in ests)


def test_the_median_offset_is_the_estimate_when_the_bound_does_not_bind():
    est = OffsetEstimator()
    assert est.median_offset_s is None
    exchange(est, 100.0, 5.0, 0.001, 0.020, 0.001)
    exchange(est, 101.0, 5.0, 0.002, 0.020, 0.001)
    assert est.median_offset_s == est.offset_s


def test_a_stepped_clock_is_followed_by_the_newest_exchanges_that_agree():
    # GIVEN 200 exchanges with a peer whose clock agrees with ours (2-3 ms legs), then its
    # clock steps 0.5 s ahead (a system clock set by hand) and 10 more exchanges arrive
    est = OffsetEstimator()
    t1 = 100.0
    for k in range(200):
        exchange(est, t1, 0.0, 0.002 + 0.001 * (k % 2), 0.005, 0.002)
        t1 += 0.02
    assert est.offset_s == pytest.approx(0.0, abs=0.001)
    for _ in range(10):
        exchange(est, t1, 0.5, 0.002, 0.005, 0.003)
        t1 += 0.02
    # THEN the window's exchanges contradict each other, and the estimate is the step's, kept
    # inside what the 10 newest allow (not the oldest or fastest exchange's)
    assert est.offset_s == pytest.approx(0.4995, abs=1e-9)
    assert est.median_offset_s == pytest.approx(0.4995, abs=1e-9)
    low, high = est.interval_s
    assert low == pytest.approx(0.497, abs=1e-9) and high == pytest.approx(0.502, abs=1e-9)
    assert est.uncertainty_s == pytest.approx(0.0025, abs=1e-9)
    assert est.rtt_s == pytest.approx(0.005, abs=1e-9)
