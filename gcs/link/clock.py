"""One vehicle's clock as the ground station sees it: offset, drift, round trip, true data age.

A telemetry sample carries the time the vehicle took it (``time_boot_ms``, the vehicle's boot
clock). Its receive time on the ground station's monotonic clock minus that stamp is

    rx - t_vehicle = offset(t_vehicle) + delay,

the clocks' offset (which drifts: PX4 SITL's lockstep clock ran 1.2 % slow) plus the delay the
sample spent in the autopilot's queues and on the link. The delay is never below the link's
least one-way delay, so the *lower envelope* of those differences is offset + least delay. The
envelope is tracked as a straight line in vehicle time, fitted to the minimum of every
`BIN_S` bin over the last `WINDOW_BINS` bins; bins more than `SPIKE_S` above the first fit are
dropped and the line refitted, so a delay spike of a few seconds does not lift the envelope. A
delay increase that lasts longer than about half the window becomes the new envelope: without a
round-trip measurement no filter can tell a lasting delay from a clock step.

The least one-way delay comes from TIMESYNC round trips (request ts1 = our send time in ns, the
vehicle answers with its own time in tc1 and ts1 echoed): half the least round trip of the last
`RTT_WINDOW` replies. Without replies it is 0, and ages are then lower bounds by that much.
A lasting rise of the delay (the latest `RECENT_ROUND_TRIPS` round trips all more than
`LASTING_RISE_S` above the least before them) drops the older ones at once, and lifts the
envelope (every kept bin) by the least delay's rise, so their difference, the clocks' offset,
stays put and ages stay true through the rise. Otherwise the old least round trip would outlive
the rise by a whole window while the envelope lifted in a few seconds: ages low by the rise.
A rise on the uplink alone lifts the envelope too far; the next samples lower it again.

The time a sample was taken, on the ground station's clock, is

    t_gcs = t_vehicle + envelope(t_vehicle) - least_delay,

never later than its receive time; its *true age* at ``now`` is ``now - t_gcs``. A vehicle clock
that jumps back by more than `RESET_S` (a reboot; reordered packets step back far less)
restarts the filter.

`LinkRoundTrips` keeps a link's round trips for the flight report and feeds them to the filter,
leaving out replies that a stopped vehicle (or host) held and released together (`BUNCHED`).
Pure: times are arguments, nothing reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Width of one envelope bin [s, vehicle time].
BIN_S = 1.0
#: Bins in the envelope fit (the window is WINDOW_BINS x BIN_S of vehicle time).
WINDOW_BINS = 20
#: Bins before the drift is fitted; before that the envelope is the least difference seen.
MIN_FIT_BINS = 3
#: A bin minimum this far above the first fit is a delay spike, not the envelope [s].
SPIKE_S = 3e-3
#: A vehicle time this far behind the newest stamp restarts the filter (a reboot) [s].
RESET_S = 1.0
#: TIMESYNC replies whose least round trip gives the least one-way delay.
RTT_WINDOW = 20
#: TIMESYNC replies whose median is the link's recent round trip (the delay rule's): a lasting
#: delay shows in every reply, one reply a loaded machine holds up does not move the median.
RECENT_ROUND_TRIPS = 3
#: The latest RECENT_ROUND_TRIPS round trips all this far above the least before them are a
#: lasting rise of the link's delay, not jitter [s].
LASTING_RISE_S = 0.02
#: Round trips kept for the flight report (at 2 Hz: over five hours).
MAX_ROUND_TRIPS = 40_000
#: Two TIMESYNC replies whose arrivals are closer than this fraction of their requests' spacing
#: came bunched: held, then released together (see `LinkRoundTrips.on_reply`).
BUNCHED = 0.25
#: The counters `LinkRoundTrips.counts` returns (fields of the proxy's ProxyCounters).
ROUND_TRIP_COUNTERS = ("timesync_replies", "timesync_bunched")


@dataclass(frozen=True, slots=True)
class ClockEstimate:
    """The filter's current view (for the report)."""

    synced: bool  # at least one sample seen
    offset_s: float  # ground-station time minus vehicle time at the newest sample, least delay out
    drift_ppm: float  # how much faster the ground station's clock runs (0 until fitted)
    least_delay_s: float  # half the least recent TIMESYNC round trip (0 without replies)
    rtt_samples: int
    resets: int
    delay_rises: int  # lasting rises of the round trip that restarted the least one


class VehicleClock:
    """Lower-envelope offset/drift filter on sample stamps, plus TIMESYNC round trips."""

    def __init__(self) -> None:
        self._line_out: np.ndarray | None = None
        self._bins_t = np.empty(WINDOW_BINS)  # vehicle time of each bin's minimum (ring)
        self._bins_o = np.empty(WINDOW_BINS)  # that minimum of rx - t_vehicle
        self._nbins = 0
        self._head = 0
        self._reset_state()
        self.resets = 0
        self._rtt = np.empty(RTT_WINDOW)
        self._rtt_sent = np.empty(RTT_WINDOW)  # when each round trip's request went out [s]
        self._rtt_link = np.ones(RTT_WINDOW, dtype=bool)  # False: it measured a stop, not the link
        self._nrtt = 0
        self._rtt_total = 0  # replies ever
        self._rtt_head = 0  # the ring's next slot; while not full, the round trips are [0, head)
        #: lasting rises of the delay: each dropped the older round trips, lifted the envelope
        self.delay_rises = 0
        self._least_delay_s = 0.0
        #: the newest TIMESYNC round trip [s] (NaN before the first): a request that waits
        #: behind a backlog on its way out waits with the setpoints
        self.last_round_trip_s = math.nan
        #: the median of the latest `RECENT_ROUND_TRIPS` round trips of the link [s] (of those
        #: there are; NaN before the first)
        self.recent_round_trip_s = math.nan

    def bind_line(self, out: np.ndarray) -> None:
        """Keep the line of :meth:`sample_time_s`, (a, b, t_ref, least delay) with a NaN while
        not synced, written into ``out`` (a row of 4 of a team's array): a caller mapping many
        vehicles' stamps reads them all at once."""
        self._line_out = out
        self._publish()

    def _publish(self) -> None:
        if self._line_out is not None:
            self._line_out[:] = (self._a, self._b, self._t_ref, self._least_delay_s)

    def _reset_state(self) -> None:
        self._nbins = 0
        self._head = 0
        self._t_ref = math.nan  # vehicle time origin of the fit (precision)
        self._bin_end = -math.inf
        self._cur_t = math.nan
        self._cur_o = math.inf
        self._last_t = -math.inf
        self._a = math.nan  # envelope = a + b (t - t_ref)
        self._b = 0.0
        self._publish()

    # --- input ----------------------------------------------------------------------------------

    def on_sample(self, t_vehicle_s: float, rx_s: float) -> None:
        """A sample stamped ``t_vehicle_s`` (vehicle boot clock) received at ``rx_s``."""
        if not (math.isfinite(t_vehicle_s) and math.isfinite(rx_s)) or t_vehicle_s < 0.0:
            return
        if self._t_ref == self._t_ref and t_vehicle_s < self._last_t - RESET_S:
            self._reset_state()
            self.resets += 1
        if self._t_ref != self._t_ref:
            self._t_ref = t_vehicle_s
            self._bin_end = t_vehicle_s + BIN_S
            self._publish()
        self._last_t = max(self._last_t, t_vehicle_s)
        o = rx_s - t_vehicle_s
        if t_vehicle_s >= self._bin_end:
            self._close_bin()
            self._bin_end = t_vehicle_s + BIN_S
        if o < self._cur_o:
            self._cur_o, self._cur_t = o, t_vehicle_s
        if self._nbins < MIN_FIT_BINS:  # before the fit: the least difference seen so far
            least = self._cur_o if self._nbins == 0 else min(self._cur_o, self._a)
            if least != self._a or self._b != 0.0:
                self._a, self._b = least, 0.0
                self._publish()

    def on_round_trip(self, rtt_s: float, sent_s: float = math.nan, *,
                      of_link: bool = True) -> None:
        """A TIMESYNC reply that came back ``rtt_s`` after its request, sent at ``sent_s``
        (the caller's clock; NaN: unknown). ``of_link=False``: the reply was held by a stop of
        the vehicle or host; it still bounds the clock offset, but `round_trips_s` and
        `last_round_trip_s` leave it out."""
        if not (math.isfinite(rtt_s) and rtt_s >= 0.0):
            return
        self._rtt[self._rtt_head] = rtt_s
        self._rtt_sent[self._rtt_head] = sent_s
        self._rtt_link[self._rtt_head] = of_link
        self._rtt_head = (self._rtt_head + 1) % RTT_WINDOW
        self._rtt_total += 1
        if of_link:
            self.last_round_trip_s = rtt_s
        self._nrtt = min(self._nrtt + 1, RTT_WINDOW)
        rose = self._nrtt > RECENT_ROUND_TRIPS and self._drop_before_a_lasting_rise()
        self._update_recent()
        least = 0.5 * float(self._rtt[: self._nrtt].min())
        if rose:
            self._lift_envelope(least - self._least_delay_s)
        self._least_delay_s = least
        self._publish()

    def _drop_before_a_lasting_rise(self) -> bool:
        k = RECENT_ROUND_TRIPS
        newest_first = (self._rtt_head - 1 - np.arange(self._nrtt)) % RTT_WINDOW
        latest = newest_first[:k][::-1]  # oldest first
        if (not self._rtt_link[latest].all()
                or self._rtt[latest].min() <= self._rtt[newest_first[k:]].min() + LASTING_RISE_S):
            return False
        for ring in (self._rtt, self._rtt_sent, self._rtt_link):
            ring[:k] = ring[latest]
        self._nrtt, self._rtt_head = k, k
        self.delay_rises += 1
        return True

    def _lift_envelope(self, rise_s: float) -> None:
        """The least delay rose by ``rise_s`` for good: the envelope (offset + least delay) with
        it, every kept bin too, so envelope - least delay, the clocks' offset, stays put."""
        if not (rise_s > 0.0 and self.synced):
            return
        self._bins_o[: self._nbins] += rise_s
        self._cur_o += rise_s
        self._a += rise_s

    def _close_bin(self) -> None:
        if not math.isfinite(self._cur_o):
            return
        self._bins_t[self._head] = self._cur_t - self._t_ref
        self._bins_o[self._head] = self._cur_o
        self._head = (self._head + 1) % WINDOW_BINS
        self._nbins = min(self._nbins + 1, WINDOW_BINS)
        self._cur_o, self._cur_t = math.inf, math.nan
        if self._nbins >= MIN_FIT_BINS:
            self._fit()
        else:
            self._a = float(self._bins_o[: self._nbins].min())
        self._publish()

    def _fit(self) -> None:
        t, o = self._bins_t[: self._nbins], self._bins_o[: self._nbins]
        b, a = np.polyfit(t, o, 1)
        keep = o - (a + b * t) <= SPIKE_S
        if 2 <= keep.sum() < keep.size:
            b, a = np.polyfit(t[keep], o[keep], 1)
        # the envelope lies below every kept minimum: lower the line onto the lowest of them
        a += min(0.0, float((o[keep] - (a + b * t[keep])).min()))
        self._a, self._b = float(a), float(b)

    # --- output ---------------------------------------------------------------------------------

    @property
    def synced(self) -> bool:
        return self._a == self._a

    @property
    def least_delay_s(self) -> float:
        return self._least_delay_s

    def disown_last_round_trip(self) -> None:
        """The latest round trip measured a stop, not the link (its reply came bunched with the
        next one): `round_trips_s` and `recent_round_trip_s` leave it out from now on."""
        if self._nrtt:
            self._rtt_link[(self._rtt_head - 1) % RTT_WINDOW] = False
            self._update_recent()

    def _update_recent(self) -> None:
        recent = self.round_trips_s()[-RECENT_ROUND_TRIPS:]
        self.recent_round_trip_s = float(np.median(recent)) if recent.size else math.nan

    def round_trips_s(self, since_s: float = -math.inf) -> np.ndarray:
        """The last (up to RTT_WINDOW) round trips of the link, oldest first; with ``since_s``,
        only those whose request went out at or after it (on the clock ``on_round_trip`` was
        given). Round trips that measured a stop (``of_link=False``) are left out."""
        k = self._rtt_head if self._nrtt == RTT_WINDOW else 0
        trips = np.roll(self._rtt[: self._nrtt], -k)
        keep = np.roll(self._rtt_link[: self._nrtt], -k)
        if since_s != -math.inf:
            keep &= np.roll(self._rtt_sent[: self._nrtt], -k) >= since_s
        return trips[keep]

    def sample_time_s(self, t_vehicle_s: float, rx_s: float) -> float:
        """When a sample stamped ``t_vehicle_s`` and received at ``rx_s`` was taken, on the
        ground station's clock (``rx_s`` itself before the first sample, or for a bad stamp)."""
        if not self.synced or not math.isfinite(t_vehicle_s):
            return rx_s
        env = self._a + self._b * (t_vehicle_s - self._t_ref)
        return min(rx_s, t_vehicle_s + env - self._least_delay_s)

    def estimate(self) -> ClockEstimate:
        offset = (self._a + self._b * (self._last_t - self._t_ref) - self._least_delay_s
                  if self.synced else math.nan)
        return ClockEstimate(self.synced, offset, 1e6 * self._b, self._least_delay_s,
                             self._rtt_total, self.resets, self.delay_rises)


class LinkRoundTrips:
    """Every TIMESYNC round trip of one link (up to `MAX_ROUND_TRIPS`, for the flight report),
    each also given to the link's `VehicleClock`; counts the replies (``timesync_replies``) and
    those that came bunched (``timesync_bunched``)."""

    def __init__(self, clock: VehicleClock) -> None:
        self._clock = clock
        self._round_trips: list[float] = []
        self._last_reply = (-math.inf, -math.inf, False)  # request and reply time, recorded
        self._n = dict.fromkeys(ROUND_TRIP_COUNTERS, 0)

    def counts(self) -> dict[str, int]:
        """The counters of `ROUND_TRIP_COUNTERS`, by name."""
        return dict(self._n)

    def round_trips_s(self) -> np.ndarray:
        """Every round trip of the link [s], oldest first (bunched replies left out)."""
        return np.asarray(self._round_trips, dtype=float)

    def on_reply(self, sent_s: float, rx_s: float) -> None:
        """The reply to a request sent at ``sent_s`` arrived at ``rx_s`` (one clock; a reply
        before its request is ignored)."""
        if rx_s < sent_s:
            return
        self._n["timesync_replies"] += 1
        # A link delays replies; it does not bunch them. Replies to requests a period apart that
        # arrive together were held by a vehicle (or host) that stopped for a while: their round
        # trips measure that stop, not the link, and both leave the link's record.
        last_sent, last_rx, last_kept = self._last_reply
        bunched = rx_s - last_rx < BUNCHED * (sent_s - last_sent)
        if bunched:
            self._n["timesync_bunched"] += 1
            if last_kept:  # the reply before this one was the bunch's first
                self._n["timesync_bunched"] += 1
                self._clock.disown_last_round_trip()
                if self._round_trips:
                    self._round_trips.pop()
        elif len(self._round_trips) < MAX_ROUND_TRIPS:
            self._round_trips.append(rx_s - sent_s)
        self._clock.on_round_trip(rx_s - sent_s, sent_s, of_link=not bunched)
        self._last_reply = (sent_s, rx_s, not bunched)
