"""The loop criteria at the link delay that exists: measured in preflight, judged per vehicle
(`DelayJudge`: the cascade criterion of rates and attitude mode; `TorqueDelayJudge`: the torque
loop's of actuators mode).

`prepare` checks each control mode at the configured delay (`fly.link_delay_s`). In preflight the
links' TIMESYNC round trips (gcs.link.clock) say what the delay is; where it exceeds the
configured one, the criterion (gcs/control/cascade.py) is evaluated again at the measured delay
and a mode that fails there is refused with one line, naming the setting that passes.

The measured one-way delay is half the lower quartile of the link's latest round trips (8, 4 s at
2 Hz): a latency that lasts shows in every round trip, while a busy machine delays some replies
by 10-20 ms (seen with two test workers and a compile on two cores) and a quartile passes over
those. It is judged only when it exceeds `fly.link_delay_s` by more than `DELAY_TOLERANCE_S`
(the criterion's 0.4 modulus margin is a design margin, not the edge of stability), at the
measured delay rounded up to `DELAY_STEP_S` (5 ms: on the safe side by less than the tolerance,
and coarse enough that a team's links, whose delays differ by a few milliseconds, share one cached
verdict).

The judge is asked only when a preflight decides (`VehicleStatus.loop_problem` defers it): the
statuses are built on every tick, and a verdict there cost one evaluation of the criterion per
vehicle whose delay fell in a new 5 ms step. While 240 vehicles were being configured, the ground
station's own load spread their round trips over hundreds of steps, and the evaluations (36 ms
each then, with a large team's 16 eigenvalues, on a slow day; 4-7 ms now) stalled the event loop,
which lifted the round trips further: the vehicles' COMMAND_ACKs waited in the kernel until it
dropped them, and the configure step failed. The round trips judged are those sent since the team
was configured (the machine's `measured_since_s`; the latest 8 while fewer than 4 are that
recent); at the decision the links have settled, so a
team's links share one or two steps. Whether a mode passes at a step is cached; the refusal line,
which names the stiffest stable settings (a search over candidate gains, ~0.2-0.3 s), is built
once per step, and only for a mode that fails there.
Pure apart from its caches.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from gcs.config.modes import ControlMode
from gcs.control.cascade import AutopilotResponse, CascadeGains, cascade_margins, passes, verdict
from gcs.control.stability import MIN_DECAY_PER_S, delays_ticks, torque_margins
from gcs.mission.autopilots import PROFILES

#: Measured delays are rounded up to this step before the criterion is evaluated [s].
DELAY_STEP_S = 0.005
#: A measured delay up to this much above the configured one is flown as configured [s].
DELAY_TOLERANCE_S = 0.005
#: The latest TIMESYNC round trips judged (4 s at 2 Hz: not the replies a vehicle sent late while
#: it was still starting up).
JUDGED_ROUND_TRIPS = 8
#: Fewer round trips than this since the team was configured: the latest ones are judged,
#: whenever they were sent (two or three are too few for the quartile to pass over the replies a
#: loaded machine delays: a test flight beside two others was refused at 17 ms each way).
MIN_SETTLED_ROUND_TRIPS = 4


class RoundTrips(Protocol):
    """What the judge reads of a link (gcs.link.clock.VehicleClock)."""

    def round_trips_s(self, since_s: float = ...) -> np.ndarray: ...


def measured_delay_s(round_trips_s: np.ndarray) -> float:
    """One-way delay [s] from round trips: half their lower quartile; NaN without any."""
    return 0.5 * float(np.percentile(round_trips_s, 25)) if round_trips_s.size else math.nan


def unmeasured_delay_lines(links: Sequence[tuple[str, int, int]], timesync_period_s: float,
                           link_delay_s: float) -> list[str]:
    """One line per link (name, round trips timed, TIMESYNC requests sent) whose delay nothing
    measured: the delay rules then take the configured ``link_delay_s`` for it, which a flight
    must say rather than assume a loopback link."""
    assumed = f"the delay rules take fly.link_delay_s ({1e3 * link_delay_s:.0f} ms)"
    if timesync_period_s <= 0.0:
        return [f"link delays not measured (fly.timesync_period_s 0 sends no TIMESYNC): {assumed}"]
    return [f"{name}: no reply to its {sent} TIMESYNC requests: its link delay is not measured; "
            f"{assumed} for it" for name, timed, sent in links if timed == 0]


class DelayJudge:
    """The criterion of one flight's mode and gains, re-evaluated at measured delays."""

    def __init__(self, mode: ControlMode, gains: CascadeGains, eigenvalues: Sequence[float],
                 tick_rate_hz: float, configured_delay_s: float,
                 response: AutopilotResponse | None = None, predicted: bool = False) -> None:
        self.mode, self.gains, self.eigenvalues = mode, gains, tuple(eigenvalues)
        self.tick_rate_hz, self.configured_delay_s = tick_rate_hz, configured_delay_s
        self.response = response  # the team file's fly.response (every vehicle), else per autopilot
        self.predicted = predicted  # fly.predict: the law reads predicted states
        self._passes: dict[tuple[int, float], bool] = {}
        self._lines: dict[tuple[int, float], str] = {}

    def deferred(self, autopilot: int, clock: RoundTrips,
                 index: int = 0) -> Callable[[float], str | None]:
        """`problem` for this vehicle (of `autopilot`: the cascade is judged per autopilot, so
        `index` is unused), asked later (when a preflight decides, with the time from which
        round trips count) with the round trips its clock holds then."""
        return functools.partial(self._problem_of, autopilot, clock)

    def _problem_of(self, autopilot: int, clock: RoundTrips, since_s: float) -> str | None:
        trips = clock.round_trips_s(since_s)
        if trips.size < MIN_SETTLED_ROUND_TRIPS:  # too few to pass over a busy machine's
            trips = clock.round_trips_s()
        return self.problem(autopilot, trips[-JUDGED_ROUND_TRIPS:])

    def problem(self, autopilot: int, round_trips_s: np.ndarray) -> str | None:
        """None when the mode is stable at this link's measured delay, when the delay is within
        the configured one (and its tolerance), or when nothing was measured; otherwise the
        refusal line (one line, naming the stable settings)."""
        delay = measured_delay_s(round_trips_s)
        if not delay > self.configured_delay_s + DELAY_TOLERANCE_S:
            return None
        response = self.response
        if response is None:
            profile = PROFILES.get(autopilot)
            if profile is None:
                return None  # an unsupported autopilot is refused on its own
            response = profile.response
        step = round(math.ceil(delay / DELAY_STEP_S - 1e-9) * DELAY_STEP_S, 6)
        key = (autopilot if self.response is None else 0, step)
        if key not in self._passes:
            self._passes[key] = passes(cascade_margins(
                self.mode, self.gains, response, self.eigenvalues, self.tick_rate_hz, step,
                self.predicted))
        if self._passes[key]:
            return None
        return self._line(key, response, delay)

    def _line(self, key: tuple[int, float], response: AutopilotResponse, delay: float) -> str:
        if key not in self._lines:
            who = "this vehicle" if self.response is not None else PROFILES[key[0]].name
            self._lines[key] = verdict(self.mode, self.gains, response, self.eigenvalues,
                                       self.tick_rate_hz, key[1], who, self.predicted)[1]
        return (f"link delay measured {1e3 * delay:.0f} ms each way (TIMESYNC round trip lower "
                f"quartile {2e3 * delay:.0f} ms), more than fly.link_delay_s "
                f"{1e3 * self.configured_delay_s:.0f} ms: {self._lines[key]}")


class TorqueDelayJudge:
    """Actuators mode's discrete-time criterion (gcs/control/stability.py) again at each link's
    measured delay, per vehicle (its inertia sets how much delay its torque loop tolerates).

    The criterion covers the ground station's own lag (MAX_LOOP_DELAY_S); a link whose round trip
    (TIMESYNC lower quartile, rounded up to DELAY_STEP_S) exceeds DELAY_TOLERANCE_S adds its
    round trip to that span: the torque is computed from telemetry that came down the link and
    acts after it went up. A vehicle whose loop fails there is refused in preflight, one line."""

    def __init__(self, vehicle_ids: Sequence[int], inertias_kgm2: Sequence[Sequence[float]],
                 alpha_eps: float, alpha_omega: float, tick_rate_hz: float) -> None:
        self.vehicle_ids = tuple(int(v) for v in vehicle_ids)
        self.inertias_kgm2 = tuple(tuple(float(j) for j in row) for row in inertias_kgm2)
        self.alpha_eps, self.alpha_omega, self.tick_rate_hz = alpha_eps, alpha_omega, tick_rate_hz
        self._lines: dict[tuple[int, float], str | None] = {}

    def deferred(self, autopilot: int, clock: RoundTrips,
                 index: int = 0) -> Callable[[float], str | None]:
        """`problem` for the vehicle of row `index`, asked when a preflight decides."""
        return functools.partial(self._problem_of, index, clock)

    def _problem_of(self, index: int, clock: RoundTrips, since_s: float) -> str | None:
        trips = clock.round_trips_s(since_s)
        if trips.size < MIN_SETTLED_ROUND_TRIPS:
            trips = clock.round_trips_s()
        return self.problem(index, trips[-JUDGED_ROUND_TRIPS:])

    def problem(self, index: int, round_trips_s: np.ndarray) -> str | None:
        """None when the vehicle's torque loop passes at its link's round trip (or the round trip
        is within DELAY_TOLERANCE_S, or nothing was measured); otherwise the refusal line."""
        delay = measured_delay_s(round_trips_s)
        if not 2.0 * delay > DELAY_TOLERANCE_S:
            return None
        step = round(math.ceil(2.0 * delay / DELAY_STEP_S - 1e-9) * DELAY_STEP_S, 6)
        key = (index, step)
        if key not in self._lines:
            self._lines[key] = self._verdict(index, step)
        line = self._lines[key]
        if line is None:
            return None
        return (f"link delay measured {1e3 * delay:.0f} ms each way (TIMESYNC round trip lower "
                f"quartile {2e3 * delay:.0f} ms): {line}")

    def _verdict(self, index: int, round_trip_s: float) -> str | None:
        vid = self.vehicle_ids[index]
        margins = torque_margins([vid], [self.inertias_kgm2[index]], self.alpha_eps,
                                 self.alpha_omega, self.tick_rate_hz, round_trip_s)
        bad = [m for m in margins if not m.ok()]
        if not bad:
            return None
        worst = max(bad, key=lambda m: m.spectral_radius)
        ticks = delays_ticks(1.0 / self.tick_rate_hz, round_trip_s)[-1]
        return (f"actuators mode at {self.tick_rate_hz:g} Hz with alpha_eps {self.alpha_eps:g}, "
                f"alpha_omega {self.alpha_omega:g} is not stable when the torque acts up to "
                f"{ticks} ticks late: axis {worst.axis} (J {worst.inertia_kgm2:g} kg m^2) has "
                f"spectral radius {worst.spectral_radius:.3f} (decay {worst.decay_per_s:.3g} /s, "
                f"need >= {MIN_DECAY_PER_S:g} /s); fly rates mode, whose attitude loop the "
                f"autopilot closes on board")
