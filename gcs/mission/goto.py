"""The go-to-start phase of `gcs fly`: where each vehicle flies, in which order, and when the team
has settled at its start positions (pure; docs/gcs.md, "Go to start").

Positions are team-frame ENU [m] (the mission machine's `VehicleStatus.position_enu_m`); the
composition root turns each target into the vehicle's own local NED frame for
SET_POSITION_TARGET_LOCAL_NED. The order is two team-wide legs, so that no two vehicles fly
across each other at one height:

1. **climb**: every vehicle goes straight up (or down) over the point where the phase found it,
   to its own start altitude; the team moves on once every one is within `tolerance_m` of it
   vertically;
2. **across**: every vehicle flies horizontally, at its start altitude, to its start position.

Vertical legs are flown over the vehicles' own (distinct) take-off points and all end before the
first horizontal leg begins, so paths can only cross between vehicles whose start altitudes are
within `separation_m` of each other; `crossing_pairs` names those whose horizontal legs also come
closer than that (the machine notes them as a warning).

Settled: every vehicle within `tolerance_m` of its start position and slower than
`max_speed_mps`, continuously for `settle_s`; not settled after `timeout_s`: the flight stops with
one line per vehicle not settled (distance, speed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]

#: Position setpoints stream this long before the position mode is commanded (PX4 only needs one
#: setpoint younger than COM_OF_LOSS_T; streaming first proves the stream reaches the vehicle).
LEAD_S = 0.5


@dataclass(frozen=True, slots=True)
class GoToStartPlan:
    """The team file's `fly.go_to_start` and every vehicle's start position (team ENU [m])."""

    starts_enu_m: tuple[tuple[int, Vec3], ...]  # (vehicle id, its initial.position_enu_m)
    enabled: str = "auto"  # auto: the vehicles that took off | true: every vehicle | false
    tolerance_m: float = 0.3
    max_speed_mps: float = 0.2
    settle_s: float = 2.0
    timeout_s: float = 60.0
    separation_m: float = 1.0  # crossing_pairs: closer than this at similar altitudes
    lead_s: float = LEAD_S

    def start_of(self, vehicle_id: int) -> Vec3:
        return dict(self.starts_enu_m)[vehicle_id]

    def flown(self, took_off: Sequence[int], every: Sequence[int]) -> tuple[int, ...]:
        """The vehicles that go to their start: those that took off in this flight (auto), all
        (true), or none (false)."""
        if self.enabled == "true":
            return tuple(every)
        if self.enabled == "auto":
            return tuple(took_off)
        return ()


@dataclass(frozen=True, slots=True)
class GotoResult:
    """One vehicle's go-to-start, for the records: where it went, how far from it and how fast
    it was at the end, how long it took from the phase start [s], and whether it settled."""

    target_enu_m: Vec3
    error_m: float
    speed_mps: float
    duration_s: float
    settled: bool


@dataclass(slots=True)
class _Leg:
    start_enu_m: Vec3
    entry_enu_m: Vec3
    settled_at_s: float | None = None  # first time within tolerance and slow (this stretch)


def _norm(v: Sequence[float]) -> float:
    return math.sqrt(sum(float(x) * float(x) for x in v))


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return _norm([x - y for x, y in zip(a, b, strict=True)])


def _segment_distance_2d(p1: Sequence[float], p2: Sequence[float], q1: Sequence[float],
                         q2: Sequence[float]) -> float:
    """Shortest distance between the horizontal segments p1-p2 and q1-q2 [m] (x, y only)."""
    def point_segment(p: Sequence[float], a: Sequence[float], b: Sequence[float]) -> float:
        ax, ay, bx, by = a[0], a[1], b[0], b[1]
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        t = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy)
                                                   / length2))
        return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)

    def orient(a: Sequence[float], b: Sequence[float], c: Sequence[float]) -> float:
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    if d1 * d2 < 0.0 and d3 * d4 < 0.0:
        return 0.0
    return min(point_segment(p1, q1, q2), point_segment(p2, q1, q2),
               point_segment(q1, p1, p2), point_segment(q2, p1, p2))


def crossing_pairs(entries_enu_m: Mapping[int, Sequence[float]],
                   starts_enu_m: Mapping[int, Sequence[float]],
                   separation_m: float) -> list[tuple[int, int, float]]:
    """(i, j, closest horizontal distance [m]) for the vehicles whose horizontal legs (entry
    x, y -> start x, y, flown at the start altitude) come closer than `separation_m` while their
    start altitudes differ by less than it: the only legs of the two-leg order that can meet."""
    ids = sorted(starts_enu_m)
    out = []
    for a, i in enumerate(ids):
        for j in ids[a + 1:]:
            if abs(starts_enu_m[i][2] - starts_enu_m[j][2]) >= separation_m:
                continue
            d = _segment_distance_2d(entries_enu_m[i], starts_enu_m[i], entries_enu_m[j],
                                     starts_enu_m[j])
            if d < separation_m:
                out.append((i, j, d))
    return out


@dataclass(slots=True)
class GoToStart:
    """The team's progress through the phase (module docstring). `update` with the vehicles'
    positions and velocities (team ENU) at each machine tick."""

    plan: GoToStartPlan
    started_s: float
    legs: dict[int, _Leg]
    stage: str = "climb"  # climb | across
    results: dict[int, GotoResult] = field(default_factory=dict)

    @classmethod
    def begin(cls, plan: GoToStartPlan, now_s: float,
              positions_enu_m: Mapping[int, Sequence[float]]) -> GoToStart:
        legs = {vid: _Leg(plan.start_of(vid), tuple(float(x) for x in p))
                for vid, p in positions_enu_m.items()}
        return cls(plan, now_s, legs)

    def target(self, vehicle_id: int) -> Vec3:
        """Where the vehicle is sent now (team ENU [m])."""
        leg = self.legs[vehicle_id]
        if self.stage == "climb":
            return (leg.entry_enu_m[0], leg.entry_enu_m[1], leg.start_enu_m[2])
        return leg.start_enu_m

    def distance_m(self, vehicle_id: int, position_enu_m: Sequence[float]) -> float:
        """Straight-line distance to the start position [m]."""
        return _distance(position_enu_m, self.legs[vehicle_id].start_enu_m)

    def update(self, now_s: float, positions_enu_m: Mapping[int, Sequence[float]],
               velocities_enu_mps: Mapping[int, Sequence[float]]) -> bool:
        """Advance; True once every vehicle has settled at its start (results then filled)."""
        tol = self.plan.tolerance_m
        if self.stage == "climb":
            if all(abs(positions_enu_m[vid][2] - leg.start_enu_m[2]) <= tol
                   for vid, leg in self.legs.items()):
                self.stage = "across"
            return False
        for vid, leg in self.legs.items():
            close = self.distance_m(vid, positions_enu_m[vid]) <= tol
            slow = _norm(velocities_enu_mps[vid]) <= self.plan.max_speed_mps
            if close and slow:
                leg.settled_at_s = leg.settled_at_s if leg.settled_at_s is not None else now_s
            else:
                leg.settled_at_s = None
        done = all(leg.settled_at_s is not None and now_s - leg.settled_at_s >= self.plan.settle_s
                   for leg in self.legs.values())
        if done:
            self._record(now_s, positions_enu_m, velocities_enu_mps, settled=True)
        return done

    def timed_out(self, now_s: float) -> bool:
        return now_s - self.started_s > self.plan.timeout_s

    def _record(self, now_s: float, positions_enu_m: Mapping[int, Sequence[float]],
                velocities_enu_mps: Mapping[int, Sequence[float]], settled: bool) -> None:
        for vid, leg in self.legs.items():
            p, v = positions_enu_m.get(vid), velocities_enu_mps.get(vid)
            ok = p is not None and v is not None
            self.results[vid] = GotoResult(
                leg.start_enu_m, self.distance_m(vid, p) if ok else math.nan,
                _norm(v) if ok else math.nan,
                (leg.settled_at_s if settled and leg.settled_at_s is not None else now_s)
                - self.started_s,
                settled and leg.settled_at_s is not None)

    def not_settled_lines(self, now_s: float, names: Mapping[int, str],
                          positions_enu_m: Mapping[int, Sequence[float]],
                          velocities_enu_mps: Mapping[int, Sequence[float]]) -> list[str]:
        """After the timeout: one line per vehicle not settled (its distance and speed), and
        the results recorded as not settled."""
        self._record(now_s, positions_enu_m, velocities_enu_mps, settled=False)
        waiting = [vid for vid, leg in self.legs.items()
                   if leg.settled_at_s is None or self.stage == "climb"] or list(self.legs)
        out = []
        for vid in waiting:
            leg, r = self.legs[vid], self.results[vid]
            s = leg.start_enu_m
            out.append(f"{names[vid]}: {r.error_m:.2f} m from its start ({s[0]:.2f}, "
                       f"{s[1]:.2f}, {s[2]:.2f}) m at {r.speed_mps:.2f} m/s (need <= "
                       f"{self.plan.tolerance_m:g} m and <= {self.plan.max_speed_mps:g} m/s for "
                       f"{self.plan.settle_s:g} s; {self.stage} leg)")
        return out

    def settled_line(self) -> str:
        worst_vid = max(self.results, key=lambda vid: self.results[vid].error_m)
        worst = self.results[worst_vid]
        longest = max(r.duration_s for r in self.results.values())
        return (f"go to start: all {len(self.results)} vehicles settled within "
                f"{self.plan.tolerance_m:g} m of their start positions after {longest:.1f} s "
                f"(largest error {worst.error_m:.3f} m, vehicle {worst_vid})")


def going_line(name: str, start_enu_m: Sequence[float], position_enu_m: Sequence[float]) -> str:
    """'vehicle 2 (sysid 2): going to start (5.00, 0.00, 5.00) m, 12.3 m away'."""
    s = start_enu_m
    return (f"{name}: going to start ({s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f}) m, "
            f"{_distance(position_enu_m, s):.1f} m away")
