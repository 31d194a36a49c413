"""Fleet runner: fixed-step loop with an injected clock, driving plant, autopilots and telemetry.

``Emulator`` is the composition of n ``VehicleNode``s over one batched ``FleetPlant``. Its
``advance_to(sim_time_s)`` is pure bookkeeping (no I/O but the links' ``send``): physics in whole
steps, autopilot logic at ``AUTOPILOT_RATE_HZ``, faults, telemetry. ``run`` paces it with a
``Clock`` (real time, scaled real time) and measures step lateness and CPU use.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from vehicle_emulator.autopilots.demand import Severity
from vehicle_emulator.autopilots.node import VehicleNode
from vehicle_emulator.config.params import ParamStore, param_table
from vehicle_emulator.config.personality import personality_of
from vehicle_emulator.config.team import FaultSpec, VehicleSpec
from vehicle_emulator.fleet.assemble import assemble_vehicle
from vehicle_emulator.mavlink.codec import HotDecoder
from vehicle_emulator.mavlink.fleet_status import FleetStatus
from vehicle_emulator.mavlink.server import LinkPoller, UdpLink
from vehicle_emulator.mavlink.telemetry import Telemetry
from vehicle_emulator.physics.geodesy import DEFAULT_ORIGIN_LLA
from vehicle_emulator.physics.plant import FleetPlant

log = logging.getLogger(__name__)

__all__ = ["STREAM_MODES", "Clock", "Emulator", "LinkPlan", "RealtimeClock", "RunStats"]

AUTOPILOT_RATE_HZ = 50.0
MAX_CATCHUP_S = 0.1
LOCKSTEP_TIMEOUT_S = 0.25
STREAM_MODES = ("default", "requested")


class Clock(Protocol):
    """Source of the emulator's time (seconds, starts near 0)."""

    def now_s(self) -> float:
        """Current time."""

    async def sleep_until(self, t_s: float) -> None:
        """Return at (or soon after) time ``t_s``."""


class RealtimeClock:
    """Monotonic wall time times ``factor`` (2.0: twice as fast as real time)."""

    def __init__(self, factor: float = 1.0) -> None:
        if not factor > 0.0:
            raise ValueError(f"realtime factor must be > 0, got {factor}")
        self.factor = factor
        self._t0 = time.monotonic()

    def now_s(self) -> float:
        return (time.monotonic() - self._t0) * self.factor

    async def sleep_until(self, t_s: float) -> None:
        delay = (t_s - self.now_s()) / self.factor
        await asyncio.sleep(max(delay, 0.0))


@dataclass(frozen=True, slots=True)
class LinkPlan:
    """UDP addresses of one vehicle: the API link and an optional GCS link. ``connect``: a link
    whose bind port is 0 is a connected socket on an ephemeral port (ArduPilot SITL's
    udpclient); one with a port binds it and answers whoever sent last (as PX4)."""

    bind: tuple[str, int]
    remote: tuple[str, int]
    gcs_bind: tuple[str, int] | None = None
    gcs_remote: tuple[str, int] | None = None
    connect: bool = False


# per autopilot family: the node class, the autopilot state machine, parameter names
@dataclass(slots=True)
class RunStats:
    """Pacing figures of a run: tick lateness [s] and CPU time."""

    ticks: int = 0
    lockstep_timeouts: int = 0
    late_max_s: float = 0.0
    late_sum_s: float = 0.0
    late_over_1ms: int = 0
    dropped_s: float = 0.0
    lateness_samples: list[float] = field(default_factory=list)

    def record(self, late_s: float) -> None:
        self.ticks += 1
        self.late_sum_s += late_s
        self.late_max_s = max(self.late_max_s, late_s)
        if late_s > 1e-3:
            self.late_over_1ms += 1
        if len(self.lateness_samples) < 200_000:
            self.lateness_samples.append(late_s)


class _Pace:
    """The real-time tick of ``Emulator.run``: ``tick_if_due`` advances the emulator to the
    clock's time when the next tick is due (lateness recorded), and is a no-op before."""

    def __init__(self, emulator: Emulator, clock: Clock, stats: RunStats) -> None:
        self.emulator = emulator
        self.clock = clock
        self.stats = stats
        self.next_tick_s = clock.now_s()
        self.offset_s = 0.0  # simulated time dropped after falling too far behind

    def tick_if_due(self) -> None:
        now = self.clock.now_s()
        if now < self.next_tick_s:
            return
        emu = self.emulator
        self.stats.record(now - self.next_tick_s)
        target = now - self.offset_s
        if target - emu.now_s > MAX_CATCHUP_S:
            skip = target - emu.now_s - MAX_CATCHUP_S
            self.offset_s += skip
            self.stats.dropped_s += skip
            target -= skip
        emu.advance_to(target)
        self.next_tick_s += emu.tick_s
        if self.next_tick_s < self.clock.now_s():
            self.next_tick_s = self.clock.now_s()


def _renumbered(spec: VehicleSpec, shift: int) -> VehicleSpec:
    """A spare copy of ``spec`` with another vehicle id and sysid (warm-up fleets only)."""
    return replace(spec, vehicle_id=spec.vehicle_id + 1000 * shift,
                   sysid=(spec.sysid + shift - 1) % 254 + 1)


class _NullLink:
    name = "null"

    def send(self, data: bytes, addr: Any = None) -> None:
        """Discard."""


class Emulator:
    """n vehicles, one batched plant, one telemetry scheduler."""

    def __init__(
        self,
        specs: Sequence[VehicleSpec],
        faults: Sequence[FaultSpec] = (),
        physics_rate_hz: float = 1000.0,
        tick_s: float = 0.002,
        seed: int = 0,
        param_overrides: dict[str, float] | None = None,
        message_intervals_ms: dict[int, float] | None = None,
        streams: str = "default",
        origin_lla: tuple[float, float, float] = DEFAULT_ORIGIN_LLA,
    ) -> None:
        """``message_intervals_ms``: ArduPilot's message-intervals file (msgid -> interval),
        preloaded into every ardupilot vehicle's streams. ``streams``: ``default`` (each
        personality's streams from boot) or ``requested`` (HEARTBEAT only, every other stream
        off until the ground station asks for it: Telemetry.requested_only). ``origin_lla``: the
        team frame's origin on the globe (lat deg, lon deg, alt m; the team file's
        ``frame.origin``)."""
        if streams not in STREAM_MODES:
            raise ValueError(f"streams: expected one of {', '.join(STREAM_MODES)}, got {streams!r}")
        sysids = [s.sysid for s in specs]
        if len(set(sysids)) != len(sysids):
            raise ValueError(f"duplicate sysids {sysids}: ground stations would merge them")
        self.specs = list(specs)
        self.plant = FleetPlant(specs, dt_s=1.0 / physics_rate_hz)
        self.tick_s = max(tick_s, self.plant.dt_s)
        self.status = FleetStatus.create(sysids)
        self.telemetry = Telemetry(len(specs), np.random.default_rng(seed), origin_lla=origin_lla)
        self.link_up = np.ones(len(specs), dtype=bool)
        self.nodes: list[VehicleNode] = []
        self._next_autopilot_s = 0.0
        self._next_deadline_s = math.inf  # the earliest autopilot deadline_s, or earlier
        families = {personality_of(s.autopilot).protocol.family for s in specs}
        for name in param_overrides or {}:  # an unknown name is refused once, not per vehicle
            if not any(name in {p.name for p in param_table(f)} for f in families):
                ParamStore.for_family(sorted(families)[0]).definition(name)
        for i, spec in enumerate(specs):
            self.nodes.append(assemble_vehicle(
                i, spec, [f for f in faults if f.vehicle_id == spec.vehicle_id], self.plant,
                self.telemetry, self.status, seed=seed, param_overrides=param_overrides or {},
                message_intervals_ms=message_intervals_ms or {}, streams=streams))
        self.links: list[UdpLink] = []
        self.poller: LinkPoller | None = None
        self._setpoint_event: asyncio.Event | None = None
        self._fault_nodes = [node for node in self.nodes if not node.faults.idle]
        self._battery_capacity_c = np.array([node.battery_capacity_c for node in self.nodes])
        # nodes with a second COMMAND_ACK queued, by index (a dataclass == on a node compares
        # every field: a list's `in` cost a fleet's burst of DO_SET_MODEs seconds)
        self._ack_nodes: dict[int, VehicleNode] = {}

    def warm_up(self) -> None:
        """Load/compile every JIT kernel the run will call, on throwaway fleets, so that nothing
        compiles after the ready line (call before starting the clock).

        numba specialises a kernel per array layout, and the layout of a view depends on the
        number of rows: a column of an (n, 3) array is contiguous for n = 1 and strided for
        n >= 2, for the whole fleet and for the subsets of it a tick works on (the vehicles of
        one personality, those with a message due). So the spares are one vehicle, one vehicle
        of each personality the fleet has, and two of each: every layout this fleet can hand a
        kernel, whatever its size."""
        kinds = list({spec.autopilot: spec for spec in self.specs}.values())
        for specs in (kinds[:1], kinds, kinds + [_renumbered(s, len(kinds)) for s in kinds]):
            spare = Emulator(specs, physics_rate_hz=1.0 / self.plant.dt_s, tick_s=self.tick_s)
            for node in spare.nodes:
                node.links.append(_NullLink())
            spare.advance_to(0.05)
        HotDecoder().decode([b""])  # the receive side's batch kernel

    @property
    def now_s(self) -> float:
        """Simulated time [s]."""
        return self.plant.time_s

    # --- the tick ------------------------------------------------------------------------------

    def advance_to(self, t_s: float) -> int:
        """Run physics up to ``t_s`` (whole steps), then autopilots, faults and telemetry.
        Returns the number of physics steps taken."""
        if self._ack_nodes:
            self.send_deferred_acks()
        steps = int(math.floor(t_s / self.plant.dt_s + 1e-9)) - self.plant.steps_done
        if steps <= 0:
            return 0
        self._step_through_deadlines(steps)
        now = self.now_s
        for node in self._fault_nodes:
            node.apply_faults(now)
        if now >= self._next_deadline_s:
            self._expire(now)
        if now + 1e-9 >= self._next_autopilot_s:
            self._next_autopilot_s = now + 1.0 / AUTOPILOT_RATE_HZ
            rows = []
            for node, seen in zip(self.nodes, self.observe_fleet(), strict=True):
                node.autopilot.tick(now, seen)
                node.apply_demand()
                node.drain_events()
                rows.append(node.status_row(now))
                node.refresh_extra(now)
                node.tick_fault_clock(now)
                node.report_input(now)
                node.announce_origin(now)
                self.link_up[node.index] = not node.impairment.is_down(now)
            # each vehicle's status as its refresh_status would write it; nothing in the loop
            # reads another vehicle's, nor its own again
            self.status.write_rows(rows)
            self.status.refresh_battery(self.plant.charge_used_c, self.plant.thrust_n,
                                        self._battery_capacity_c)
            self._fault_nodes = [node for node in self.nodes if not node.faults.idle]
        out = self.telemetry.collect(now, self.plant, self.status, self.link_up)
        for i, data in out.items():
            self.nodes[i].send_all(data)
        return steps

    def observe_fleet(self) -> list[Any]:
        """Every vehicle's `VehicleNode.observe`, gathered from the fleet's arrays at once (the
        same values: at 240 vehicles and 50 Hz, a node's own indexing of them cost 7 % of the
        fleet's time). Exact as the tick uses it: a vehicle's tick changes no other's plant
        state or battery."""
        p, ob = self.plant, self.plant.onboard
        est = ob.sensor_model.astype(bool)
        pos = np.where(est[:, None], ob.position_est_enu_m, p.position_enu_m).tolist()
        vel = np.where(est[:, None], ob.velocity_est_enu_mps, p.velocity_enu_mps).tolist()
        rot = np.where(est[:, None, None], ob.rotation_est, p.rotation)
        r10, r00 = rot[:, 1, 0].tolist(), rot[:, 0, 0].tolist()
        ground, tilt = p.on_ground.tolist(), p.rotation[:, 2, 2].tolist()
        battery = self.status.battery_remaining.tolist()
        seen = []
        for node in self.nodes:
            i = node.index
            seen.append(node.observation(tuple(pos[i]), tuple(vel[i]), math.atan2(r10[i], r00[i]),
                                         bool(ground[i]), battery[i], tilt[i]))
        return seen

    def _step_through_deadlines(self, steps: int) -> None:
        """``steps`` physics steps, stopping at each autopilot deadline that falls inside them
        to expire what is due: a late wake-up that catches up 20 ms at once must not fly an
        expired guided target for those 20 ms (ArduCopter drops it on the 400 Hz pass after
        GUID_TIMEOUT, whatever its ground station's link does). It stops the same way at each
        scheduled fault: a mass drop acts from the first step at or after its time, however
        late the wake-up."""
        plant = self.plant
        while True:
            fault_s = min((node.faults.next_due_s() for node in self._fault_nodes),
                          default=math.inf)
            stop_s = min(self._next_deadline_s, fault_s)
            run = steps
            if stop_s < math.inf:
                due = math.ceil((stop_s - plant.time_s) / plant.dt_s - 1e-9)
                run = min(steps, max(due, 1))
            plant.step(run)
            steps -= run
            if steps == 0:
                return
            if plant.time_s >= fault_s - 1e-9:
                for node in self._fault_nodes:
                    node.apply_faults(plant.time_s)
            if plant.time_s >= self._next_deadline_s:
                self._expire(plant.time_s)

    def _expire(self, now_s: float) -> None:
        """What fell due between autopilot ticks (a guided target's timeout), before this step's
        telemetry reports it; then the next deadline."""
        for node in self.nodes:
            if node.autopilot.deadline_s <= now_s:
                node.autopilot.expire(now_s, node.observe())
                node.apply_demand()
        self._next_deadline_s = min(node.autopilot.deadline_s for node in self.nodes)

    def send_deferred_acks(self) -> None:
        """Second COMMAND_ACKs queued by the commands handled since the last tick (DO_SET_MODE
        with EMU_ACK_TWICE = 1): the next tick, a tick period after the first ACK at most."""
        nodes, self._ack_nodes = self._ack_nodes, {}
        for node in nodes.values():
            node.send_deferred_acks(self.now_s)

    def on_messages(self, node: VehicleNode, link: Any, msgs: list[Any], addr: Any) -> None:
        """Decoded messages from one link of one vehicle."""
        now = self.now_s
        for msg in msgs:
            node.handle(now, msg, link, addr)
        if node.autopilot.deadline_s < self._next_deadline_s:
            self._next_deadline_s = node.autopilot.deadline_s
        if node.deferred_acks:
            self._ack_nodes.setdefault(node.index, node)
        if self._setpoint_event is not None:
            self._setpoint_event.set()

    # --- I/O -----------------------------------------------------------------------------------

    async def open_links(self, plans: Sequence[LinkPlan], clock: Clock) -> None:
        """Bind every vehicle's UDP endpoints (OSError names the address on failure); one
        ``LinkPoller`` reads them all."""
        if self.poller is None:
            self.poller = LinkPoller()
        for node, plan in zip(self.nodes, plans, strict=True):
            pairs = [("api", plan.bind, plan.remote)]
            if plan.gcs_bind is not None and plan.gcs_remote is not None:
                pairs.append(("gcs", plan.gcs_bind, plan.gcs_remote))
            for kind, bind, remote in pairs:
                name = f"vehicle {node.spec.vehicle_id} {kind} {bind[0]}:{bind[1]}"

                def deliver(link: UdpLink, msgs: list[Any], addr: Any, node=node) -> None:
                    self.on_messages(node, link, msgs, addr)

                try:
                    link = await UdpLink.open(
                        bind, remote, node.impairment, clock.now_s, deliver, name=name,
                        connect=plan.connect and bind[1] == 0,
                    )
                except OSError as exc:
                    raise OSError(f"{name}: cannot bind: {exc}") from exc
                if link.connected:
                    host, port = link.local_address or bind
                    link.name = f"vehicle {node.spec.vehicle_id} {kind} {host}:{port}"
                for data in node.boot_banner():  # before any MAVLink (ArduPilot SITL)
                    link.send(data)
                self.poller.attach(link)
                node.links.append(link)
                self.links.append(link)

    def close_links(self) -> None:
        """Close every socket."""
        if self.poller is not None:
            self.poller.close()
        for link in self.links:
            link.close()

    async def run(self, clock: Clock, stop: asyncio.Event, stats: RunStats | None = None) -> None:
        """Pace ``advance_to`` with ``clock`` until ``stop`` is set. The tick comes first: a
        tick that falls due while the poller delivers a batch of datagrams runs between two
        of them (``LinkPoller.between``), not after the batch (at 240 vehicles a setpoint burst
        is ~3 ms of work, and the telemetry of a tick that waited for it went out that late)."""
        stats = stats if stats is not None else RunStats()
        pace = _Pace(self, clock, stats)
        for node in self.nodes:
            node.statustext(
                Severity.INFO,
                f"vehicle-emu {node.spec.vehicle_id} ready, {node.autopilot.mode_name}",
            )
        if self.poller is not None:
            self.poller.between = pace.tick_if_due
        try:
            while not stop.is_set():
                pace.tick_if_due()
                await clock.sleep_until(pace.next_tick_s)
        finally:
            if self.poller is not None:
                self.poller.between = None

    async def run_lockstep(
        self, clock: Clock, stop: asyncio.Event, stats: RunStats | None = None
    ) -> None:
        """Lockstep with the ground station: while any vehicle is armed in OFFBOARD, simulated
        time advances one tick only when every such vehicle has received a new setpoint (the
        GCS's control period drives the simulation, however slow or fast it runs); when no
        vehicle is in OFFBOARD, or no setpoint comes within LOCKSTEP_TIMEOUT_S of wall time (a
        silent GCS), time follows ``clock`` so that heartbeats, takeoffs and the offboard-loss
        failsafe still happen."""
        stats = stats if stats is not None else RunStats()
        self._setpoint_event = asyncio.Event()
        seen = [node.setpoints_taken for node in self.nodes]
        t_last = clock.now_s()
        for node in self.nodes:
            node.statustext(Severity.INFO, f"vehicle-emu {node.spec.vehicle_id} ready, lockstep")
        while not stop.is_set():
            driving = [n for n in self.nodes if n.setpoint_driven()]
            step = self.tick_s
            if driving:
                deadline = clock.now_s() + LOCKSTEP_TIMEOUT_S
                while not all(n.setpoints_taken > seen[n.index] for n in driving):
                    if self._ack_nodes:  # simulated time waits; the second ACK does not
                        self.send_deferred_acks()
                    self._setpoint_event.clear()
                    left = deadline - clock.now_s()
                    if left <= 0 or stop.is_set():
                        stats.lockstep_timeouts += 1
                        step = max(self.tick_s, min(clock.now_s() - t_last, 1.0))
                        break
                    try:
                        await asyncio.wait_for(self._setpoint_event.wait(), left)
                    except TimeoutError:
                        continue
                seen = [node.setpoints_taken for node in self.nodes]
            else:
                await clock.sleep_until(t_last + self.tick_s)
                step = max(self.tick_s, min(clock.now_s() - t_last, MAX_CATCHUP_S))
            t_last = clock.now_s()
            stats.record(0.0)
            self.advance_to(self.now_s + step)
            await asyncio.sleep(0)
