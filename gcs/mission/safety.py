"""Pure safety checks of `gcs fly`: preflight (before arming / offboard) and in-flight rules.

Every check takes plain values (a `VehicleStatus` per vehicle, the rules from the team file) and
returns `Problem`s naming the vehicle, the value and the limit; nothing here reads a clock or a
socket. Frames: positions ENU [m], tilt = angle between body z and world z [rad].
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from gcs.mission.autopilots import PX4_AUTOPILOT as PX4_AUTOPILOT  # re-exported
from gcs.mission.autopilots import profile_for, unsupported_text

QUADROTOR_TYPE = 2
#: A vehicle moving faster than this is not "holding" before the formation starts [m/s].
MAX_START_SPEED_MPS = 1.5
#: A telemetry stream must reach this fraction of its requested rate in preflight.
RATE_TOLERANCE = 0.5
#: A vehicle's link delay over `max_data_age_s` stops the flight once it has been over it at
#: every check for this long [s] (`SustainedDelays`): shorter than the half second a link may
#: fall silent before it is lost (`link_lost_after_s`), so late data is flown no longer than
#: none would be.
DELAY_SUSTAINED_S = 0.25


@dataclass(frozen=True, slots=True)
class Problem:
    """Why the flight cannot go on. `vehicle_id` is None for a team-level problem."""

    vehicle_id: int | None
    text: str
    kind: str = "check"  # check | ready | link | delay | geofence | tilt | mode | follow
    # ready: not yet (a stream or the position estimate still missing, e.g. ArduPilot before its
    # EKF uses GPS); preflight waits for it on the ground, up to fly.arm_timeout_s

    def __str__(self) -> str:
        return self.text


@dataclass(slots=True)
class VehicleStatus:
    """One vehicle as the mission sees it at a tick (from its link, as received); a snapshot
    nothing writes to after it is made (not frozen only because a frozen dataclass takes ~3 us
    longer to build, times every vehicle at every check: a tick's worth at 240 vehicles).

    link: 'waiting' | 'alive' | 'lost'; mode: e.g. 'OFFBOARD', 'AUTO_LOITER', 'GUIDED_NOGPS';
    landed: True on the ground, False in the air, None unknown; data_age_s: time since the older of
    its position and attitude samples arrived (liveness); delay_s: how long after the vehicle took
    them they arrived (from its own stamps, gcs.link.clock: the link's delay, not the gap since);
    rates_hz: measured receive rate per message type;
    listen: where the ground station listens for it (e.g. 'udp 127.0.0.1:14540'), for messages;
    landed_state: MAV_LANDED_STATE (0 unknown, 1 ON_GROUND, 2 IN_AIR, 3 TAKEOFF, 4 LANDING);
    prearm_ok: SYS_STATUS MAV_SYS_STATUS_PREARM_CHECK health, None when not reported;
    status_text: the vehicle's latest STATUSTEXT (severity and text quoted, '' if none);
    height_above_home_m: GLOBAL_POSITION_INT.relative_alt, the autopilot's own height above its
    home (PX4 and ArduPilot put home where they arm: the takeoff point); NaN when not sent.
    """

    vehicle_id: int
    sysid: int
    link: str
    armed: bool = False
    mode: str = ""
    landed: bool | None = None
    position_enu_m: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    velocity_enu_mps: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    tilt_rad: float = math.nan
    data_age_s: float = math.inf
    delay_s: float = math.inf
    #: its recent TIMESYNC round trip [s]: the median of the latest 3 (gcs.link.clock; NaN: none
    #: yet): minus delay_s, how late what the ground station sends reaches the vehicle (its
    #: setpoints included)
    round_trip_s: float = math.nan
    autopilot: int = 0
    vehicle_type: int = 0
    sysid_mismatch: int | None = None
    rates_hz: Mapping[str, float] = field(default_factory=dict)
    listen: str = ""
    landed_state: int = 0
    prearm_ok: bool | None = None
    status_text: str = ""
    height_above_home_m: float = math.nan
    # its local frame's tie to the team frame (gcs.fly.origins): why there is none (None: tied),
    # and whether the origin is still awaited
    frame_problem: str | None = None
    frame_pending: bool = False
    # the cascade criterion at this link's measured delay (gcs/fly/delay.py), asked only when a
    # preflight decides (costly), with the time from which the link's round trips count: None,
    # or the line saying why the control mode is not stable
    loop_problem: Callable[[float], str | None] | None = None

    @property
    def name(self) -> str:
        return f"vehicle {self.vehicle_id} (sysid {self.sysid})"

    @property
    def in_air(self) -> bool:
        return self.landed is False


@dataclass(frozen=True, slots=True)
class SafetyRules:
    """Limits from the team file's `fly:` section (see gcs.config.FlyConfig)."""

    max_tilt_rad: float = 1.0
    link_lost_after_s: float = 0.5
    #: in flight: position/attitude arriving this long after they were taken stop the formation
    max_data_age_s: float = 0.3
    geofence_min_enu_m: tuple[float, float, float] | None = None
    geofence_max_enu_m: tuple[float, float, float] | None = None
    #: message type -> minimum rate [Hz] required in preflight
    required_rates_hz: Mapping[str, float] = field(default_factory=dict)
    #: HEARTBEAT.autopilot -> why the control mode is not stable on it (gcs/control/cascade.py)
    loop_refusals: Mapping[int, str] = field(default_factory=dict)


def tilt_rad(rotation_enu_flu: np.ndarray) -> float:
    """Angle between body z and world z: acos(R[2, 2]) (NaN for a NaN rotation)."""
    c = float(rotation_enu_flu[2, 2])
    return math.acos(max(-1.0, min(1.0, c))) if math.isfinite(c) else math.nan


def geofence_problem(status: VehicleStatus, rules: SafetyRules) -> Problem | None:
    """The vehicle outside the geofence box (or its position unknown while one is set)."""
    lo, hi = rules.geofence_min_enu_m, rules.geofence_max_enu_m
    if lo is None or hi is None:
        return None
    p = status.position_enu_m
    for k, axis in enumerate("xyz"):
        if not lo[k] <= p[k] <= hi[k]:
            return Problem(
                status.vehicle_id,
                f"{status.name}: geofence breach: {axis} = {p[k]:.2f} m outside "
                f"[{lo[k]:g}, {hi[k]:g}] m",
                "geofence",
            )
    return None


def link_problem(status: VehicleStatus, rules: SafetyRules) -> Problem | None:
    """Lost link: the proxy says so, or no position/attitude for `link_lost_after_s`."""
    if status.link == "lost" or status.data_age_s > rules.link_lost_after_s:
        age = "never" if math.isinf(status.data_age_s) else f"{status.data_age_s:.2f} s ago"
        return Problem(
            status.vehicle_id,
            f"{status.name}: link lost (last position/attitude {age}, limit "
            f"{rules.link_lost_after_s:g} s)",
            "link",
        )
    return None


def delay_problem(status: VehicleStatus, rules: SafetyRules) -> Problem | None:
    """The vehicle's data arrives, but late: more than `max_data_age_s` after it was taken (from
    its own stamps). The law would act on where the vehicle was, not where it is. A vehicle that
    falls silent is the link rule's (its last sample's delay does not grow). Or what is sent to
    it arrives that late (its recent TIMESYNC round trip, the median of three, less its data's
    delay): the law's setpoints would act on a vehicle that has moved on. One check's verdict:
    `SustainedDelays` stops the flight on a delay that lasts."""
    if status.delay_s > rules.max_data_age_s and math.isfinite(status.delay_s):
        return Problem(
            status.vehicle_id,
            f"{status.name}: link delay: its position/attitude arrive {status.delay_s:.2f} s "
            f"after they were taken (limit {rules.max_data_age_s:g} s, fly.max_data_age_s)",
            "delay",
        )
    # the other way: its data is fresh, but what we send queues on the way (a radio's or the
    # vehicle's input buffer): the law's setpoints act that much later than it assumes
    uplink_s = status.round_trip_s - (status.delay_s if math.isfinite(status.delay_s) else 0.0)
    if uplink_s > rules.max_data_age_s:
        return Problem(
            status.vehicle_id,
            f"{status.name}: link delay: it answers TIMESYNC {status.round_trip_s:.2f} s after "
            f"the request (median of its latest 3), so what it is sent (the setpoints) reaches "
            f"it ~{uplink_s:.2f} s late (limit {rules.max_data_age_s:g} s, fly.max_data_age_s)",
            "delay",
        )
    return None


@dataclass(slots=True)
class SustainedDelays:
    """The delay rule over time: a vehicle's delay problem counts once it has been found at
    every check for `hold_s` (`DELAY_SUSTAINED_S`). A lasting delay (a radio's queue, a link
    that got slower) is in every check and stops the flight `hold_s` later; the odd late batch
    of samples, or a reply, that a loaded machine holds up is not (the check after it finds
    the data fresh again). Times are arguments (any monotonic clock, seconds)."""

    hold_s: float = DELAY_SUSTAINED_S
    _since_s: dict[int | None, float] = field(default_factory=dict)

    def sustained(self, problems: Sequence[Problem], now_s: float) -> list[Problem]:
        """`problems` without the delay problems not yet found at every check for `hold_s`
        (the others pass as they are); a vehicle without a delay problem now starts afresh."""
        late = {p.vehicle_id for p in problems if p.kind == "delay"}
        for vid in [v for v in self._since_s if v not in late]:
            del self._since_s[vid]
        out = []
        for p in problems:
            if p.kind == "delay" and now_s - self._since_s.setdefault(p.vehicle_id, now_s) \
                    < self.hold_s:
                continue
            out.append(p)
        return out


def tilt_problem(status: VehicleStatus, rules: SafetyRules) -> Problem | None:
    if not status.tilt_rad <= rules.max_tilt_rad:
        return Problem(
            status.vehicle_id,
            f"{status.name}: tilt {math.degrees(status.tilt_rad):.1f} deg exceeds max_tilt_rad "
            f"{rules.max_tilt_rad:g} ({math.degrees(rules.max_tilt_rad):.1f} deg)",
            "tilt",
        )
    return None


def flight_problems(team: Sequence[VehicleStatus], rules: SafetyRules,
                    skip: frozenset[int] = frozenset()) -> list[Problem]:
    """In-flight rules for every vehicle not in `skip` (ids already handled): link, delay,
    geofence, tilt. Returns all problems found (empty: fly on)."""
    out: list[Problem] = []
    for s in team:
        if s.vehicle_id in skip:
            continue
        p = link_problem(s, rules)
        if p is not None:
            out.append(p)
            continue  # the other values are stale
        for check in (delay_problem, geofence_problem, tilt_problem):
            q = check(s, rules)
            if q is not None:
                out.append(q)
    return out


def preflight_problems(team: Sequence[VehicleStatus], rules: SafetyRules,
                       measured_since_s: float = -math.inf) -> list[Problem]:
    """Everything that must hold before arming or switching to offboard.

    Per vehicle: link alive, no foreign vehicle on its link, a quadrotor with a supported autopilot
    (gcs.mission.autopilots; that autopilot's own requirements, e.g. ArduPilot's GUID_OPTIONS, are
    checked by the mission machine once read), telemetry at the required rates, a finite state,
    tilt and speed within limits, inside the geofence if airborne; the control mode stable at
    each link's delay, measured from the round trips since `measured_since_s` (those of the
    vehicles' start-up, the ground station's own configure step included, do not count).
    """
    out: list[Problem] = []
    for s in team:
        n = s.name
        if s.link != "alive":
            out.append(Problem(s.vehicle_id, f"{n}: link {s.link}", "link"))
            continue
        if s.sysid_mismatch is not None:
            out.append(Problem(s.vehicle_id, f"{n}: a vehicle with sysid {s.sysid_mismatch} "
                                             "answers on this link; check the team file"))
        if profile_for(s.autopilot) is None:
            out.append(Problem(s.vehicle_id, unsupported_text(n, s.autopilot)))
        elif s.autopilot in rules.loop_refusals:
            out.append(Problem(s.vehicle_id, f"{n}: {rules.loop_refusals[s.autopilot]}"))
        elif s.loop_problem is not None and \
                (why := s.loop_problem(measured_since_s)) is not None:
            out.append(Problem(s.vehicle_id, f"{n}: {why}"))
        if s.vehicle_type != QUADROTOR_TYPE:
            out.append(Problem(s.vehicle_id, f"{n}: MAV_TYPE {s.vehicle_type} is not a quadrotor "
                                             f"({QUADROTOR_TYPE})"))
        for kind, need in rules.required_rates_hz.items():
            got = s.rates_hz.get(kind, 0.0)
            if not got >= RATE_TOLERANCE * need:
                out.append(Problem(s.vehicle_id, f"{n}: {kind} at {got:.1f} Hz, need >= "
                                                 f"{RATE_TOLERANCE * need:g} Hz (asked {need:g})",
                                   "ready"))
        if not all(math.isfinite(x) for x in (*s.position_enu_m, *s.velocity_enu_mps)):
            out.append(Problem(s.vehicle_id, f"{n}: no valid position/velocity", "ready"))
            continue
        q = tilt_problem(s, rules)
        if q is not None:
            out.append(q)
        speed = math.sqrt(sum(v * v for v in s.velocity_enu_mps))
        if speed > MAX_START_SPEED_MPS:
            out.append(Problem(s.vehicle_id, f"{n}: moving at {speed:.2f} m/s, more than "
                                             f"{MAX_START_SPEED_MPS:g} m/s before the start"))
        if s.in_air:
            g = geofence_problem(s, rules)
            if g is not None:
                out.append(g)
        if s.landed is None:
            out.append(Problem(s.vehicle_id, f"{n}: landed state unknown (no EXTENDED_SYS_STATE)"))
        if s.frame_problem is not None:
            out.append(Problem(s.vehicle_id, s.frame_problem if s.frame_problem.startswith(n)
                               else f"{n}: {s.frame_problem}",
                               "ready" if s.frame_pending else "check"))
    return out
