"""Live status of `gcs fly`: a rich table per vehicle on a terminal, one plain line otherwise.

`snapshot(flight)` reads the flight's latest values into a `StatusSnapshot` (cheap; called at the
refresh rate, not per tick); `render_table` and `plain_line` are pure formatting; `StatusView`
is the owned task that refreshes until the flight is finished.
"""

from __future__ import annotations

import asyncio
import math
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, TextIO

from gcs.mission.plan import Phase

if TYPE_CHECKING:
    from gcs.fly.flight import Flight


@dataclass(frozen=True, slots=True)
class VehicleLine:
    vehicle_id: int
    sysid: int
    mode: str
    armed: bool
    link: str
    rate_hz: float  # accepted messages per second
    age_ms: float  # true age of the older of position and attitude (taken how long ago)
    altitude_m: float
    mass_estimate_kg: float
    thrust_n: float
    streaming: bool


@dataclass(frozen=True, slots=True)
class StatusSnapshot:
    phase: str
    t_s: float | None  # formation time
    duration_s: float
    formation_error_m: float
    late_pct: float
    vehicles: tuple[VehicleLine, ...]
    note: str
    connecting: str = ""  # CONNECT phase: who has been heard, who not (MissionMachine)


class _Rate:
    """Messages/s per vehicle from the accepted-message counter between two snapshots."""

    def __init__(self) -> None:
        self._last: dict[int, tuple[float, int]] = {}

    def update(self, vid: int, now_s: float, count: int) -> float:
        prev = self._last.get(vid)
        self._last[vid] = (now_s, count)
        if prev is None or now_s <= prev[0]:
            return math.nan
        return (count - prev[1]) / (now_s - prev[0])


def snapshot(flight: Flight, rates: _Rate, now_s: float) -> StatusSnapshot:
    m = flight.machine
    streaming = m.streaming | frozenset(m.position_targets)
    tick = flight.tick
    cmd = tick.last_command
    lines = []
    for i, p in enumerate(flight.proxies):
        vid = flight.ids[i]
        s = p.state()
        count = p.stats().proxy.messages_accepted
        sample = tick.last_sample
        lines.append(VehicleLine(
            vehicle_id=vid, sysid=p.config.sysid, mode=s.mode or "-", armed=s.armed,
            link=p.link_state().value, rate_hz=rates.update(vid, now_s, count),
            age_ms=1e3 * float(sample.delay_s[i]) if sample is not None else math.nan,
            altitude_m=float(s.position_enu_m[2]),
            mass_estimate_kg=float(cmd.mass_estimate_kg[i]) if cmd is not None else math.nan,
            thrust_n=float(cmd.thrust_n[i]) if cmd is not None else math.nan,
            streaming=vid in streaming,
        ))
    return StatusSnapshot(
        phase=m.phase.value, t_s=tick.formation_t_s, duration_s=flight.setup.plan.duration_s,
        formation_error_m=tick.formation_error_m,
        late_pct=100.0 * flight.figures.ticks.late_fraction(),
        vehicles=tuple(lines), note=m.notes[-1] if m.notes else "",
        connecting=m.connect_progress() if m.phase is Phase.CONNECT else "",
    )


def _f(x: float, spec: str) -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, spec)


def plain_line(s: StatusSnapshot) -> str:
    """One line: phase, time, formation error, then per vehicle
    id:mode(* armed)/link/age/altitude/mass estimate; while connecting, who has been heard."""
    if s.connecting:
        return f"[{s.phase}] {s.connecting}"
    t = f"t={_f(s.t_s, '.1f')}/{s.duration_s:g}s" if s.t_s is not None else "t=-"
    parts = [f"[{s.phase}] {t} form_err={_f(s.formation_error_m, '.3g')}m "
             f"late={s.late_pct:.1f}%"]
    for v in s.vehicles:
        parts.append(f"{v.vehicle_id}:{v.mode}{'*' if v.armed else ''}/{v.link[0]}"
                     f"/{_f(v.age_ms, '.0f')}ms/z={_f(v.altitude_m, '.1f')}"
                     f"/m={_f(v.mass_estimate_kg, '.3f')}")
    return " ".join(parts)


def render_table(s: StatusSnapshot):  # -> rich Table (imported lazily)
    from rich.table import Table

    t = f"{_f(s.t_s, '.1f')} / {s.duration_s:g} s" if s.t_s is not None else "-"
    table = Table(title=f"gcs fly: {s.phase}   t {t}   formation error "
                        f"{_f(s.formation_error_m, '.4f')} m   late ticks {s.late_pct:.1f}%",
                  caption=s.connecting or s.note[:100], expand=False)
    for name in ("UAV", "sysid", "mode", "armed", "link", "msg/s", "age ms", "z m", "m_est kg",
                 "T N", "setpoints"):
        table.add_column(name, justify="right")
    for v in s.vehicles:
        link_style = {"alive": "green", "lost": "bold red"}.get(v.link, "yellow")
        table.add_row(str(v.vehicle_id), str(v.sysid), v.mode, "yes" if v.armed else "no",
                      f"[{link_style}]{v.link}[/]", _f(v.rate_hz, ".0f"), _f(v.age_ms, ".0f"),
                      _f(v.altitude_m, ".2f"), _f(v.mass_estimate_kg, ".3f"),
                      _f(v.thrust_n, ".2f"), "on" if v.streaming else "off")
    return table


class StatusView:
    """Owned task: refresh a rich Live table (TTY) or print a plain line every `plain_period_s`."""

    def __init__(self, flight: Flight, style: str = "auto", stream: TextIO | None = None,
                 refresh_hz: float = 4.0, plain_period_s: float = 2.0) -> None:
        self.flight = flight
        self.stream = stream or sys.stderr
        if style == "auto":
            style = "rich" if self.stream.isatty() else "plain"
        self.style = style
        self.period_s = 1.0 / refresh_hz if style == "rich" else plain_period_s
        self._rates = _Rate()

    async def run(self, finished: asyncio.Event) -> None:
        """Refresh until `finished` is set; returns then."""
        loop = asyncio.get_running_loop()
        if self.style == "off":
            await finished.wait()
            return
        if self.style == "rich":
            from rich.console import Console
            from rich.live import Live

            console = Console(file=self.stream)
            with Live(console=console, auto_refresh=False, transient=False) as live:
                while not finished.is_set():
                    live.update(render_table(snapshot(self.flight, self._rates, loop.time())),
                                refresh=True)
                    await _wait(finished, self.period_s)
            return
        while not finished.is_set():
            await _wait(finished, self.period_s)
            print(plain_line(snapshot(self.flight, self._rates, loop.time())), file=self.stream,
                  flush=True)


async def _wait(event: asyncio.Event, timeout_s: float) -> None:
    try:
        async with asyncio.timeout(timeout_s):
            await event.wait()
    except TimeoutError:
        pass
