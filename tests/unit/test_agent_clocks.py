"""A peer's clock offset from four timestamps (gcs/agent/clocks.py): closed forms, the
least-round-trip filter over its window, the error bound, refusals."""

from __future__ import annotations

import math

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


def test_the_least_round_trip_in_the_window_is_the_estimate():
    # GIVEN exchanges with round trips 10, 2 and 6 ms (asymmetric, so each gives another offset)
    est = OffsetEstimator(window=3)
    exchange(est, 0.0, 1.0, 0.008, 0.0, 0.002)
    exchange(est, 1.0, 1.0, 0.0015, 0.0, 0.0005)
    exchange(est, 2.0, 1.0, 0.001, 0.0, 0.005)
    # THEN the 2 ms one is the estimate
    assert est.rtt_s == pytest.approx(0.002) and est.offset_s == pytest.approx(1.0005)
    # WHEN three more with larger round trips push it out of the window THEN the least of those
    for t1, rtt in ((3.0, 0.009), (4.0, 0.007), (5.0, 0.008)):
        exchange(est, t1, 1.0, rtt / 2, 0.0, rtt / 2)
    assert est.samples == 3 and est.rtt_s == pytest.approx(0.007)
    assert est.offset_s == pytest.approx(1.0)


def test_exchanges_older_than_max_age_leave_the_window():
    est = OffsetEstimator(window=100, max_age_s=10.0)
    exchange(est, 0.0, 0.0, 0.0001, 0.0, 0.0001)  # the best, at t4 ~ 0
    exchange(est, 5.0, 0.0, 0.002, 0.0, 0.002)
    assert est.rtt_s == pytest.approx(0.0002) and est.samples == 2
    # WHEN one arrives more than 10 s after the best THEN the best is forgotten
    exchange(est, 10.5, 0.0, 0.003, 0.0, 0.003)
    assert est.samples == 2 and est.rtt_s == pytest.approx(0.004)


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
    # GIVEN any offset and any legs and holds THEN |estimate - offset| <= rtt_min / 2
    est = OffsetEstimator(window=16)
    t1 = 1000.0
    for up, held, down in exchanges:
        assert exchange(est, t1, offset, up, held, down)
        t1 += 0.02 + held
    tolerance = 1e-9 * max(1.0, abs(offset)) + 1e-9
    assert abs(est.offset_s - offset) <= est.uncertainty_s + tolerance
    assert est.rtt_s == pytest.approx(min(u + d for u, _, d in exchanges[-16:]), abs=tolerance)
