"""The go-to-start phase of `gcs fly`: where each vehicle flies, in which order, and when the team
has settled at its start positions (pure; docs/gcs.md, "Go to start").

Positions are team-frame ENU [m] (the mission machine's `VehicleStatus.position_enu_m`); the
composition root turns each target into the vehicle's own local NED frame for
SET_POSITION_TARGET_LOCAL_NED. The order is two team-wide legs, so that no two vehicles fly
across each other at one height:

Along each leg the setpoint moves from the leg's start at `cruise_speed_mps`, slows down at
APPROACH_DECEL_MPS2 and stops at the leg's end (a "carrot"), its velocity sent as the position
loop's feed-forward (PX4 and ArduPilot add it to their position P term): the autopilot's loop
never sees a step of more than a tick's travel, so it neither flies the leg at its maximum speed
(PX4 MPC_XY_VEL_MAX is 12 m/s) nor stops from full speed with a wound-up velocity integrator
(the px4 personality, given the whole 15 m step at once, reached 3.7 m/s and overshot by
0.5-0.7 m, then took 10 s to come back; with a 2 m/s carrot that stopped dead, still 0.65 m).

1. **climb**: every vehicle goes straight up (or down) over the point where the phase found it,
   to its own start altitude; the team moves on once every one is within `tolerance_m` of it
   vertically;
2. **across**: every vehicle flies horizontally, at its start altitude, to its start position.

Vertical legs are flown over the vehicles' own (distinct) take-off points and all end before the
first horizontal leg begins, so paths can only cross between vehicles whose start altitudes are
within `separation_m` of each other; `crossing_pairs` names those whose horizontal legs also come
closer than that (the machine notes them as a warning).

Settled, per vehicle, by either of two rules, and the team once every vehicle is at once:

* **still**: over the last `settle_s`, its mean position within `tolerance_m` of its start and
  its drift below `max_speed_mps` (how far the mean position of the window's second half lies
  from that of its first half, over the time between them). Means of positions, not every sample
  and not the reported velocity: a hovering autopilot's reported state wanders, so a
  sample-by-sample rule at these thresholds is never met while the vehicle holds still.
* **holding as its autopilot holds**: once its setpoint has rested on its start for HOLD_S, over
  that rest (the last HOLD_WINDOW_S of it): its mean position within `tolerance_m` plus its
  wander (the RMS distance of its positions from their mean) of the start, the wander at most
  MAX_WANDER_M, and the drift below `max_speed_mps`. Real PX4 SIH holds a position setpoint with
  a slow wander of 0.32-0.38 m RMS (2026-12-04 recordings: 2 s means 0.26-0.31 m from the
  setpoint at the median, their 2 s drift 0.12-0.13 m/s), so the still rule settled all four
  vehicles in only a few percent of the windows and never within 60 s; over its rest its mean
  lies 0.05-0.14 m from the setpoint and this rule holds for all four 8-9 s after their setpoints
  stopped. A vehicle whose mean rests further away than its own wander explains, or that swings
  more than MAX_WANDER_M, is not there.

Not settled after `timeout_s`: the flight stops with one line per vehicle not settled.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

Vec3 = tuple[float, float, float]

#: The setpoint slows down at this rate before each leg's end [m/s^2] (see the module docstring).
APPROACH_DECEL_MPS2 = 0.5

#: The hold rule (module docstring): judged once a vehicle's setpoint has rested on its start this
#: long [s], over at most the last HOLD_WINDOW_S of the rest, for a wander of at most MAX_WANDER_M
#: (SIH's over 20 s of rest: 0.29-0.35 m at the median, 0.43 m at most, four vehicles).
HOLD_S = 8.0
HOLD_WINDOW_S = 20.0
MAX_WANDER_M = 0.6
#: ... and recomputed at most this often [s] (a machine tick is far shorter).
HOLD_JUDGE_S = 0.25

#: Position setpoints stream this long before the position mode is commanded (PX4 only needs one
#: setpoint younger than COM_OF_LOSS_T; streaming first proves the stream reaches the vehicle).
LEAD_S = 0.5


@dataclass(frozen=True, slots=True)
class GoToStartPlan:
    """The team file's `fly.go_to_start` and every vehicle's start position (team ENU [m])."""

    starts_enu_m: tuple[tuple[int, Vec3], ...]  # (vehicle id, its initial.position_enu_m)
    enabled: str = "auto"  # auto: the vehicles that took off | true: every vehicle | false
    tolerance_m: float = 0.3
    max_speed_mps: float = 0.1
    settle_s: float = 2.0
    timeout_s: float = 60.0
    cruise_speed_mps: float = 2.0  # the setpoint moves along each leg at this speed
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
    error_m: float  # mean position's distance from the target, by the rule it settled by
    speed_mps: float  # drift [m/s], likewise
    duration_s: float
    settled: bool
    rule: str = ""  # still | holding (module docstring); "" when not settled
    wander_m: float = math.nan  # RMS distance from its mean position over its rest


@dataclass(slots=True)
class _Leg:
    start_enu_m: Vec3
    entry_enu_m: Vec3
    window: deque[tuple[float, Vec3, Vec3]] = field(default_factory=deque)  # (t, p, v)
    mean_error_m: float = math.nan  # |mean p - start| over the window
    mean_speed_mps: float = math.nan  # drift: mean position, late half vs early half [m/s]
    rest_s: float = math.inf  # when its setpoint came to rest on its start
    rest: deque[tuple[float, Vec3]] = field(default_factory=deque)  # (t, p) since then
    hold_error_m: float = math.nan  # the hold rule's figures (nan: not judged yet)
    wander_m: float = math.nan
    hold_drift_mps: float = math.nan
    judged_s: float = -math.inf  # when the hold rule's figures were last computed
    rule: str = ""  # the rule it settled by: still | holding

    def add(self, now_s: float, p: Sequence[float], v: Sequence[float], span_s: float) -> bool:
        """Keep the samples of the last `span_s` (and of the rest); True once they span it
        (means then set)."""
        sample = tuple(map(float, p))
        self.window.append((now_s, sample, tuple(map(float, v))))
        while len(self.window) > 1 and self.window[1][0] <= now_s - span_s:
            self.window.popleft()
        self.mean_error_m = _distance(_mean(w[1] for w in self.window), self.start_enu_m)
        self.mean_speed_mps = _drift([(w[0], w[1]) for w in self.window], self.window[0][2])
        if now_s >= self.rest_s:
            self.rest.append((now_s, sample))
            while len(self.rest) > 1 and self.rest[1][0] <= now_s - HOLD_WINDOW_S:
                self.rest.popleft()
            if now_s - self.rest_s >= HOLD_S and now_s - self.judged_s >= HOLD_JUDGE_S:
                self.judged_s = now_s
                rows = np.asarray([(r[0], *r[1]) for r in self.rest])
                t, pos = rows[:, 0], rows[:, 1:]
                mean = pos.mean(axis=0)
                self.hold_error_m = float(np.linalg.norm(mean - self.start_enu_m))
                self.wander_m = float(np.sqrt(((pos - mean) ** 2).sum(axis=1).mean()))
                half = len(rows) // 2
                span = t[-half:].mean() - t[:half].mean()
                self.hold_drift_mps = float(np.linalg.norm(
                    pos[-half:].mean(axis=0) - pos[:half].mean(axis=0)) / max(span, 1e-9))
        return now_s - self.window[0][0] >= span_s - 1e-9

    def settled(self, tolerance_m: float, max_speed_mps: float) -> bool:
        if self.mean_error_m <= tolerance_m and self.mean_speed_mps <= max_speed_mps:
            self.rule = "still"
        elif (self.hold_error_m <= tolerance_m + self.wander_m and self.wander_m <= MAX_WANDER_M
              and self.hold_drift_mps <= max_speed_mps):
            self.rule = "holding"
        else:
            self.rule = ""
        return bool(self.rule)


def _drift(samples: Sequence[tuple[float, Sequence[float]]], velocity: Sequence[float]) -> float:
    """How far the mean position of the samples' late half lies from that of their early half,
    per second between them [m/s]; with one sample, the speed of ``velocity``."""
    half = len(samples) // 2
    if half == 0:
        return _norm(velocity)
    early, late = samples[:half], samples[-half:]
    span = _mean([(s[0],) for s in late])[0] - _mean([(s[0],) for s in early])[0]
    return _distance(_mean(s[1] for s in late), _mean(s[1] for s in early)) / max(span, 1e-9)


def _mean(rows: Iterable[Sequence[float]]) -> list[float]:
    rows = list(rows)
    return [sum(r[k] for r in rows) / len(rows) for k in range(len(rows[0]))]


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
    stage_s: float = 0.0  # when the stage began
    results: dict[int, GotoResult] = field(default_factory=dict)

    @classmethod
    def begin(cls, plan: GoToStartPlan, now_s: float,
              positions_enu_m: Mapping[int, Sequence[float]]) -> GoToStart:
        legs = {vid: _Leg(plan.start_of(vid), tuple(float(x) for x in p))
                for vid, p in positions_enu_m.items()}
        return cls(plan, now_s, legs, stage_s=now_s)

    def leg_end(self, vehicle_id: int) -> Vec3:
        """Where the vehicle's current leg ends (team ENU [m])."""
        leg = self.legs[vehicle_id]
        if self.stage == "climb":
            return (leg.entry_enu_m[0], leg.entry_enu_m[1], leg.start_enu_m[2])
        return leg.start_enu_m

    def target(self, vehicle_id: int, now_s: float) -> tuple[Vec3, Vec3]:
        """Where the vehicle is sent at `now_s` and how fast the setpoint moves (team ENU [m],
        [m/s]; the velocity is the autopilot's feed-forward): the carrot along its leg."""
        leg = self.legs[vehicle_id]
        begin = leg.entry_enu_m if self.stage == "climb" else (
            leg.entry_enu_m[0], leg.entry_enu_m[1], leg.start_enu_m[2])
        end = self.leg_end(vehicle_id)
        length = _distance(end, begin)
        t = now_s - self.stage_s
        travel = carrot_travel_m(length, self.plan.cruise_speed_mps, APPROACH_DECEL_MPS2, t)
        if travel >= length:
            return end, (0.0, 0.0, 0.0)
        dt = 0.01
        speed = (carrot_travel_m(length, self.plan.cruise_speed_mps, APPROACH_DECEL_MPS2,
                                 t + dt) - travel) / dt
        unit = [(e - b) / length for b, e in zip(begin, end, strict=True)]
        return (tuple(b + travel * u for b, u in zip(begin, unit, strict=True)),
                tuple(speed * u for u in unit))

    def distance_m(self, vehicle_id: int, position_enu_m: Sequence[float]) -> float:
        """Straight-line distance to the start position [m]."""
        return _distance(position_enu_m, self.legs[vehicle_id].start_enu_m)

    def update(self, now_s: float, positions_enu_m: Mapping[int, Sequence[float]],
               velocities_enu_mps: Mapping[int, Sequence[float]]) -> bool:
        """Advance; True once every vehicle has settled at its start (results then filled)."""
        plan = self.plan
        if self.stage == "climb":
            if all(abs(positions_enu_m[vid][2] - leg.start_enu_m[2]) <= plan.tolerance_m
                   for vid, leg in self.legs.items()):
                self.stage, self.stage_s = "across", now_s
                for leg in self.legs.values():
                    length = _distance(leg.start_enu_m, (leg.entry_enu_m[0], leg.entry_enu_m[1],
                                                         leg.start_enu_m[2]))
                    leg.rest_s = now_s + carrot_arrival_s(length, plan.cruise_speed_mps,
                                                          APPROACH_DECEL_MPS2)
            return False
        full = [leg.add(now_s, positions_enu_m[vid], velocities_enu_mps[vid], plan.settle_s)
                for vid, leg in self.legs.items()]
        done = all(full) and all(leg.settled(plan.tolerance_m, plan.max_speed_mps)
                                 for leg in self.legs.values())
        if done:
            self._record(now_s, settled=True)
        return done

    def timed_out(self, now_s: float) -> bool:
        return now_s - self.started_s > self.plan.timeout_s

    def _record(self, now_s: float, settled: bool) -> None:
        for vid, leg in self.legs.items():
            ok = self.stage == "across" and leg.settled(self.plan.tolerance_m,
                                                        self.plan.max_speed_mps)
            holding = leg.rule == "holding"
            self.results[vid] = GotoResult(
                leg.start_enu_m, leg.hold_error_m if holding else leg.mean_error_m,
                leg.hold_drift_mps if holding else leg.mean_speed_mps, now_s - self.started_s,
                ok or settled, leg.rule, leg.wander_m)

    def not_settled_lines(self, now_s: float, names: Mapping[int, str],
                          positions_enu_m: Mapping[int, Sequence[float]]) -> list[str]:
        """After the timeout: one line per vehicle not settled (its distance from its start
        now, and its drift over the last settle_s), and the results recorded as not settled."""
        self._record(now_s, settled=False)
        waiting = [vid for vid, r in self.results.items() if not r.settled] or list(self.legs)
        out = []
        plan = self.plan
        for vid in waiting:
            leg, r = self.legs[vid], self.results[vid]
            s = leg.start_enu_m
            drift = "" if math.isnan(r.speed_mps) else f", mean {r.error_m:.2f} m and " \
                f"{r.speed_mps:.2f} m/s over the last {plan.settle_s:g} s"
            hold = "" if math.isnan(leg.wander_m) else (
                f"; over its {min(now_s - leg.rest_s, HOLD_WINDOW_S):.0f} s at rest: mean "
                f"{leg.hold_error_m:.2f} m, wander {leg.wander_m:.2f} m, drift "
                f"{leg.hold_drift_mps:.2f} m/s (need <= {plan.tolerance_m:g} m + wander, "
                f"wander <= {MAX_WANDER_M:g} m)")
            out.append(f"{names[vid]}: {self.distance_m(vid, positions_enu_m[vid]):.2f} m from "
                       f"its start ({s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f}) m{drift} (need <= "
                       f"{plan.tolerance_m:g} m and <= {plan.max_speed_mps:g} m/s{hold}; "
                       f"{self.stage} leg)")
        return out

    def settled_line(self) -> str:
        worst_vid = max(self.results, key=lambda vid: self.results[vid].error_m)
        worst = self.results[worst_vid]
        longest = max(r.duration_s for r in self.results.values())
        holding = sorted(vid for vid, r in self.results.items() if r.rule == "holding")
        if not holding:
            how = f"within {self.plan.tolerance_m:g} m"
        else:
            who = "vehicle " + ", ".join(map(str, holding)) if len(holding) < len(
                self.results) else "every vehicle"
            how = (f"{who} by the hold rule: mean over its rest within "
                   f"{self.plan.tolerance_m:g} m + its wander, largest wander "
                   f"{max(self.results[v].wander_m for v in holding):.2f} m")
        return (f"go to start: all {len(self.results)} vehicles settled at their start positions "
                f"after {longest:.1f} s ({how}; largest mean error {worst.error_m:.3f} m, "
                f"vehicle {worst_vid})")


def carrot_arrival_s(length_m: float, speed_mps: float, decel_mps2: float) -> float:
    """When the setpoint of `carrot_travel_m` comes to rest on the leg's end [s after it began]."""
    if length_m <= 0.0:
        return 0.0
    brake_m = speed_mps * speed_mps / (2.0 * decel_mps2)
    if brake_m >= length_m:
        return math.sqrt(2.0 * length_m / decel_mps2)
    return (length_m - brake_m) / speed_mps + speed_mps / decel_mps2


def carrot_travel_m(length_m: float, speed_mps: float, decel_mps2: float, t_s: float) -> float:
    """How far along a leg of `length_m` the setpoint is `t_s` after the leg began: at
    `speed_mps`, then slowing at `decel_mps2` to stop at the end (a short leg starts at the speed
    from which it can stop in time)."""
    if t_s <= 0.0 or length_m <= 0.0:
        return 0.0
    brake_m = speed_mps * speed_mps / (2.0 * decel_mps2)
    if brake_m >= length_m:
        speed_mps, brake_m = math.sqrt(2.0 * decel_mps2 * length_m), length_m
    cruise_s = (length_m - brake_m) / speed_mps
    if t_s <= cruise_s:
        return speed_mps * t_s
    tau = min(t_s - cruise_s, speed_mps / decel_mps2)
    return min(length_m, length_m - brake_m + speed_mps * tau - 0.5 * decel_mps2 * tau * tau)


def going_line(name: str, start_enu_m: Sequence[float], position_enu_m: Sequence[float]) -> str:
    """'vehicle 2 (sysid 2): going to start (5.00, 0.00, 5.00) m, 12.3 m away'."""
    s = start_enu_m
    return (f"{name}: going to start ({s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f}) m, "
            f"{_distance(position_enu_m, s):.1f} m away")
