"""The cascade criterion at the link delay that exists: measured in preflight, judged per vehicle.

`prepare` checks each control mode at the configured delay (`fly.link_delay_s`). In preflight the
links' TIMESYNC round trips (gcs.link.clock) say what the delay is; where it exceeds the
configured one, the criterion (gcs/mission/cascade.py) is evaluated again at the measured delay
and a mode that fails there is refused with one line, naming the setting that passes.

The measured one-way delay is half the lower quartile of the link's latest round trips (8, 4 s at
2 Hz): a latency that lasts shows in every round trip, while a busy machine delays some replies
by 10-20 ms (seen with two test workers and a compile on two cores) and a quartile passes over
those. It is judged only when it exceeds `fly.link_delay_s` by more than `DELAY_TOLERANCE_S`
(the criterion's 0.4 modulus margin is a design margin, not the edge of stability), at the
measured delay rounded up to `DELAY_STEP_S` (5 ms: on the safe side by less than the tolerance,
and coarse enough that a team's links, whose delays differ by a few milliseconds, share one cached
verdict).

The judge runs on the tick (every status update of the preflight), so it splits its work: whether
the mode passes at a delay costs one evaluation of the criterion (~2 ms) and is answered at once;
the refusal line, which names the stiffest stable settings, costs a search over candidate gains
(~0.2-0.3 s) and is built only when the preflight reads it, once per delay step (for a team
whose links share a step, once). Built on every
tick, that search stalled the event loop for seconds while the round trips were being measured,
and the stall, counted in the round trips, raised the measured delay itself.
Pure apart from its caches.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np

from gcs.mission.autopilots import PROFILES
from gcs.mission.cascade import AutopilotResponse, CascadeGains, cascade_margins, passes, verdict

#: Measured delays are rounded up to this step before the criterion is evaluated [s].
DELAY_STEP_S = 0.005
#: A measured delay up to this much above the configured one is flown as configured [s].
DELAY_TOLERANCE_S = 0.005


def measured_delay_s(round_trips_s: np.ndarray) -> float:
    """One-way delay [s] from round trips: half their lower quartile; NaN without any."""
    return 0.5 * float(np.percentile(round_trips_s, 25)) if round_trips_s.size else math.nan


class DelayJudge:
    """The criterion of one flight's mode and gains, re-evaluated at measured delays."""

    def __init__(self, mode: str, gains: CascadeGains, eigenvalues: Sequence[float],
                 tick_rate_hz: float, configured_delay_s: float,
                 response: AutopilotResponse | None = None, predicted: bool = False) -> None:
        self.mode, self.gains, self.eigenvalues = mode, gains, tuple(eigenvalues)
        self.tick_rate_hz, self.configured_delay_s = tick_rate_hz, configured_delay_s
        self.response = response  # the team file's fly.response (every vehicle), else per autopilot
        self.predicted = predicted  # fly.predict: the law reads predicted states
        self._passes: dict[tuple[int, float], bool] = {}
        self._lines: dict[tuple[int, float], str] = {}

    def refusal(self, autopilot: int, round_trips_s: np.ndarray) -> Callable[[], str] | None:
        """None when the mode is stable at this link's measured delay, when the delay is within
        the configured one (and its tolerance), or when nothing was measured; otherwise a
        callable that builds the refusal line (one line, naming the stable settings: the costly
        part, see the module docstring)."""
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
        return functools.partial(self._line, key, response, delay)

    def _line(self, key: tuple[int, float], response: AutopilotResponse, delay: float) -> str:
        if key not in self._lines:
            who = "this vehicle" if self.response is not None else PROFILES[key[0]].name
            self._lines[key] = verdict(self.mode, self.gains, response, self.eigenvalues,
                                       self.tick_rate_hz, key[1], who, self.predicted)[1]
        return (f"link delay measured {1e3 * delay:.0f} ms each way (TIMESYNC round trip lower "
                f"quartile {2e3 * delay:.0f} ms), more than fly.link_delay_s "
                f"{1e3 * self.configured_delay_s:.0f} ms: {self._lines[key]}")
