"""The latest state sample of each vehicle a process hears, and what it received from each
(pure: every time is an argument, on this process's monotonic clock): the latest sample wins by
seq, gaps in seq count as lost, older or repeated ones as duplicates, undecodable ones as
corrupt with their reason; each sender's clock offset from the echoes it carries.

The times a message carries are on its sender's *wire clock*: its monotonic clock, or, with
network.clocks disciplined, its system clock (the monotonic one plus `wire_shift()`, the
system clock's lead over it, read when needed). The echoes measure the offset between two
processes' wire clocks. How a sender's times reach this process's clock (ClockMode):

- measured: by that offset, estimated (gcs/agent/clocks.py);
- disciplined: by none (the hosts' clocks agree, as PTP or chrony keep them), less our own
  shift; the exchanges only check it: a sender whose offset every one of at least
  CHECK_EXCHANGES exchanges puts further than `tolerance_s` from 0 has a `clock_problem`, and
  its samples get no time here (they are stale, never flown on). The check reads the interval
  the exchanges allow, not the estimate: a path slower one way than the other moves the
  estimate by half the difference (the supervisor's link plain and an agent's delayed 20 ms
  reads as a 10 ms offset), but never moves the true offset out of that interval;
- one-host: by none (every process's monotonic clock is one).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from gcs.agent.clocks import OffsetEstimator
from gcs.agent.control import MAX_TEXT, EdgeFigures
from gcs.agent.wire import SUPERVISOR_ID, Echo, StateSample, WireError, decode
from gcs.config.modes import ClockMode

#: Messages of one sender kept to echo. A process echoes each message once per own publisher
#: (gcs/agent/clocks.py says why every one); one that publishes less often than the sender
#: echoes only the newest this many.
ECHO_BACKLOG = 16
#: With clocks disciplined: the exchanges a sender's clock is checked on before it is judged
#: (a fraction of a second at the tick rate; the interval fewer allow is too wide to prove much).
CHECK_EXCHANGES = 16


def no_shift() -> float:
    """The wire clock is the monotonic one."""
    return 0.0


@dataclass(frozen=True, slots=True)
class Rows:
    """The latest state of vehicles `ids`, one row each in that order (world ENU, body FLU).
    `taken_local_s`: when the vehicle took the sample, on this process's clock (the sender's
    taken_s less its clock offset; -inf before the first sample, and before the first offset
    when clocks are synchronised); `received_s`: when it arrived here (-inf before);
    `age_s = now - taken_local_s` (inf before); `finite`: the row holds a sample with a known
    time (the other arrays hold NaN where it does not)."""

    ids: tuple[int, ...]
    position_enu_m: np.ndarray  # (k, 3)
    velocity_enu_mps: np.ndarray  # (k, 3)
    acceleration_enu_mps2: np.ndarray  # (k, 3)
    attitude_wxyz: np.ndarray  # (k, 4) FLU -> ENU
    omega_flu_radps: np.ndarray  # (k, 3)
    taken_local_s: np.ndarray  # (k,)
    received_s: np.ndarray  # (k,)
    age_s: np.ndarray  # (k,)
    finite: np.ndarray  # (k,) bool

    def fresh(self, max_age_s: float) -> np.ndarray:
        """(k,) bool: the rows with a sample at most `max_age_s` old."""
        return self.finite & (self.age_s <= max_age_s)


@dataclass(slots=True)
class _Edge:
    """What this process knows of one sender."""

    sample: StateSample | None = None
    received_s: float = -np.inf  # when `sample` arrived
    last_received_s: float = -np.inf  # when the sender's latest message arrived
    # the sender's latest messages to echo, oldest first: (their number here, sent_s, arrival)
    backlog: deque[tuple[int, float, float]] = field(
        default_factory=lambda: deque(maxlen=ECHO_BACKLOG))
    heard_count: int = 0  # messages heard from the sender (the backlog's numbering)
    received: int = 0
    lost: int = 0
    duplicates: int = 0
    corrupt: int = 0
    restarts: int = 0
    corrupt_reason: str | None = None
    clock: OffsetEstimator = field(default_factory=OffsetEstimator)


class SampleTable:
    """The senders `senders` as this process hears them. `local_ids`: the ids whose messages
    this process sends (its own vehicles, or the supervisor's id): an echo naming one of them
    is an exchange with its sender. `team_ids`: the ids a sample's vehicle and echoes may
    name. `clocks`, `tolerance_s` and `wire_shift`: how senders' times reach this process's
    clock (module docstring); `wire_shift` is used with clocks disciplined only."""

    def __init__(self, senders: Iterable[int], *, local_ids: Collection[int],
                 team_ids: Collection[int] | None = None,
                 clocks: ClockMode = ClockMode.MEASURED, tolerance_s: float = 0.005,
                 wire_shift: Callable[[], float] = no_shift) -> None:
        self._edges = {vid: _Edge() for vid in senders}
        self._echoed: dict[int, dict[int, int]] = {}  # publisher -> sender -> last echoed
        self.local_ids = frozenset(local_ids)
        self.team_ids = None if team_ids is None else frozenset(team_ids)
        self.clocks = ClockMode(clocks)
        self.tolerance_s = tolerance_s
        self.wire_shift = wire_shift if self.clocks is ClockMode.DISCIPLINED else no_shift

    @property
    def senders(self) -> tuple[int, ...]:
        return tuple(self._edges)

    def _edge(self, vid: int) -> _Edge:
        try:
            return self._edges[vid]
        except KeyError:
            raise KeyError(f"vehicle {vid} is not heard here (senders: "
                           f"{', '.join(map(str, self._edges))})") from None

    def corrupt(self, vid: int, reason: str) -> None:
        """Count a message from `vid` that could not be used, with its reason."""
        edge = self._edge(vid)
        edge.corrupt += 1
        edge.corrupt_reason = reason[:MAX_TEXT]

    def receive(self, vid: int, data: bytes, received_s: float) -> StateSample | None:
        """Take bytes that arrived at `received_s` on vehicle `vid`'s key: the sample if it is
        the newest of `vid`, else None (counted as corrupt or duplicate; never raises for the
        bytes)."""
        edge = self._edge(vid)
        try:
            sample = decode(data, self.team_ids)
        except WireError as exc:
            self.corrupt(vid, exc.reason)
            return None
        if sample.vehicle_id != vid:
            self.corrupt(vid, f"vehicle id {sample.vehicle_id} on the key of vehicle {vid}")
            return None
        last = edge.sample
        if last is not None and sample.epoch != last.epoch:
            edge.restarts += 1  # a new process: its seq starts again, its clock may differ
            edge.clock.reset()
            edge.backlog.clear()
        elif last is not None and sample.seq <= last.seq:
            edge.duplicates += 1
            return None
        elif last is not None:
            edge.lost += sample.seq - last.seq - 1
        edge.received += 1
        edge.sample, edge.received_s = sample, received_s
        self.heard(vid, sample.sent_s, received_s, sample.echoes)
        return sample

    def heard(self, vid: int, sent_s: float, received_s: float,
              echoes: Sequence[Echo] = ()) -> None:
        """A message from `vid` sent at `sent_s` (its wire clock) arrived at `received_s`
        (ours), carrying `echoes`: each that names one of `local_ids` is a clock exchange
        between the two wire clocks."""
        edge = self._edge(vid)
        edge.last_received_s = received_s
        edge.heard_count += 1
        edge.backlog.append((edge.heard_count, sent_s, received_s))
        exchanges = [e for e in echoes if e.peer_id in self.local_ids]
        if exchanges:
            received_wire_s = received_s + self.wire_shift()
            for e in exchanges:
                edge.clock.add(e.sent_s, sent_s - e.held_s, sent_s, received_wire_s)

    def echoes(self, now_s: float, publisher: int,
               per_sender: int = ECHO_BACKLOG) -> tuple[Echo, ...]:
        """The echoes for `publisher`'s (one of `local_ids`) message sent at `now_s`: every
        message heard since its last echoes (the newest `per_sender` of each sender, at most
        ECHO_BACKLOG), each held until `now_s`."""
        echoed = self._echoed.setdefault(publisher, {})
        out = []
        for vid, e in self._edges.items():
            last = echoed.get(vid, 0)
            new = [Echo(vid, sent_s, max(0.0, now_s - received_s))
                   for n, sent_s, received_s in e.backlog if n > last]
            out += new[max(0, len(new) - per_sender):]
            echoed[vid] = e.heard_count
        return tuple(out)

    def clock(self, vid: int) -> OffsetEstimator:
        """`vid`'s clock filter (read it; the table feeds it)."""
        return self._edge(vid).clock

    def latest(self, vid: int) -> StateSample | None:
        return self._edge(vid).sample

    def last_heard_s(self, vid: int) -> float:
        """When the latest message of `vid` arrived (our clock); -inf before the first."""
        return self._edge(vid).last_received_s

    def offset(self, vid: int) -> float | None:
        """The offset used to convert `vid`'s times (its wire clock - ours): the measured one
        (None before the first exchange); 0 with clocks disciplined (None while `vid` has a
        clock problem) or on one host."""
        if self.clocks is ClockMode.MEASURED:
            return self._edge(vid).clock.offset_s
        if self.clocks is ClockMode.DISCIPLINED and self.clock_problem(vid) is not None:
            return None
        return 0.0

    def to_local(self, vid: int, peer_s: float) -> float:
        """Time `peer_s` of `vid`'s wire clock on our monotonic clock; -inf while its offset
        is not known."""
        offset = self.offset(vid)
        return -np.inf if offset is None else peer_s - offset - self.wire_shift()

    def to_local_agreed(self, vid: int, peer_s: float) -> float:
        """Time `peer_s` of `vid`'s wire clock on ours by the median offset (OffsetEstimator's
        `median_offset_s`) where offsets are measured: for an instant that every process of the
        team converts alike (the formation start); -inf while the offset is not known."""
        if self.clocks is ClockMode.MEASURED:
            offset = self._edge(vid).clock.median_offset_s
        else:
            offset = self.offset(vid)
        return -np.inf if offset is None else peer_s - offset - self.wire_shift()

    def clock_problem(self, vid: int) -> str | None:
        """With clocks disciplined: why `vid`'s clock cannot be taken as ours (at least
        CHECK_EXCHANGES exchanges, each of which puts its offset further than `tolerance_s`
        from 0 on the same side), in one line; None when it can, not yet judged, or in another
        mode."""
        if self.clocks is not ClockMode.DISCIPLINED:
            return None
        clock = self._edge(vid).clock
        interval = clock.interval_s
        if clock.samples < CHECK_EXCHANGES or interval is None:
            return None
        low, high = interval
        if low > self.tolerance_s:
            least, side = low, "ahead of"
        elif high < -self.tolerance_s:
            least, side = -high, "behind"
        else:
            return None
        who = "the supervisor's clock" if vid == SUPERVISOR_ID else f"vehicle {vid}'s clock"
        return (f"{who} is at least {least * 1e3:.1f} ms {side} ours by {clock.samples} echoes "
                f"(network.clocks disciplined, tolerance {self.tolerance_s * 1e3:g} ms): "
                "synchronise the hosts' clocks (PTP, chrony) or set network.clocks measured")

    def clock_known(self, vid: int) -> bool:
        """Whether `vid`'s times can be put on our clock: its offset measured (measured), its
        clock checked on CHECK_EXCHANGES exchanges and found within the tolerance
        (disciplined), always on one host."""
        if self.clocks is ClockMode.MEASURED:
            return self._edge(vid).clock.offset_s is not None
        if self.clocks is ClockMode.DISCIPLINED:
            return (self._edge(vid).clock.samples >= CHECK_EXCHANGES
                    and self.clock_problem(vid) is None)
        return True

    def figures(self, vid: int) -> EdgeFigures:
        e = self._edge(vid)
        return EdgeFigures(vid, e.received, e.lost, e.duplicates, e.corrupt, e.restarts,
                           e.corrupt_reason, e.clock.offset_s, e.clock.uncertainty_s)

    def stats(self) -> dict[int, EdgeFigures]:
        """Per sender, what arrived from it and its measured clock offset."""
        return {vid: self.figures(vid) for vid in self._edges}

    def rows(self, ids: Sequence[int], now_s: float) -> Rows:
        """The latest state of vehicles `ids` at `now_s` (our clock); KeyError naming an id
        that is not a sender."""
        k = len(ids)
        state = np.full((k, 16), np.nan)
        taken = np.full(k, -np.inf)
        received = np.full(k, -np.inf)
        for row, vid in enumerate(ids):
            edge = self._edge(vid)
            s = edge.sample
            if s is None:
                continue
            received[row] = edge.received_s
            taken[row] = self.to_local(vid, s.taken_s)
            state[row] = (*s.position_enu_m, *s.velocity_enu_mps, *s.acceleration_enu_mps2,
                          *s.attitude_wxyz, *s.omega_flu_radps)
        finite = np.isfinite(taken)
        state[~finite] = np.nan
        age = np.where(finite, now_s - taken, np.inf)
        return Rows(tuple(ids), state[:, 0:3], state[:, 3:6], state[:, 6:9], state[:, 9:13],
                    state[:, 13:16], taken, received, age, finite)
