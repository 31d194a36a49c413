"""Lifetime of one `gcs fly` flight: links, the mission machine, the tick, commands, records.

One asyncio event loop owns everything through an `asyncio.TaskGroup`:

* one `VehicleProxy` per vehicle (codec + UDP endpoint + telemetry cache + acked commands),
* the control tick (gcs/fly/tick.py: `TickLoop`, `Tick`): absolute deadlines t0 + k h (never
  `sleep(h)`, so it does not drift), lateness measured; each tick snapshots every vehicle's
  telemetry as received, steps the pure `MissionMachine`, runs the WHOLE team's law in one
  vectorised `TeamLaw.step`, and sends each streaming vehicle its setpoint (gcs/fly/setpoints.py),
* one task per command the machine asks for (gcs/fly/commander.py; its result goes back to the
  machine),
* the live status (gcs/fly/status.py) and, on a terminal, the abort key.

Each vehicle is commanded through its autopilot's profile (gcs.mission.autopilots: PX4 OFFBOARD /
ArduPilot GUIDED_NOGPS, their hold, land and takeoff recipes), which the machine fixes at preflight
from the vehicle's HEARTBEAT; a team may mix autopilots. The set-up policy is gcs/fly/setup.py,
the records gcs/fly/records.py.

Ctrl-C / SIGTERM / the abort key become `MissionMachine.request_abort`; the machine then lands or
holds every vehicle and keeps streaming to each until it has left offboard. If the flight code
itself fails, `_emergency_stop` still sends the abort action to every vehicle before the links
close. See docs/architecture.md and docs/gcs.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import signal
import sys
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np

from flightkit.latecompile import watch_late_compiles
from gcs.config import ControlMode, FlyAction, TeamConfig
from gcs.control.predict import PredictionAudit
from gcs.fly.commander import Commander
from gcs.fly.consistent import AccelerationConsistency, VelocityConsistency
from gcs.fly.origins import (
    TeamTies,
    origin_from_gps_global_origin,
    origin_from_home_position,
)
from gcs.fly.records import TLOG_NAME, Figures, Records, flight_log_builder
from gcs.fly.sched import Scheduling, leave_realtime
from gcs.fly.setpoints import Setpoints
from gcs.fly.setup import FlightSetup, FlightSetupError, FlyOptions, FlyResult, prepare
from gcs.fly.stats import AgeStats, TickStats
from gcs.fly.tick import LawRows, Tick, TickLoop, build_law, warm_up
from gcs.geodesy import Geodetic, TeamFrame
from gcs.link import (
    CommandRejectedError,
    CommandTimeoutError,
    HotTable,
    LinkClosedError,
    MavlinkPort,
    TlogWriter,
    VehicleLinkConfig,
    VehicleProxy,
    check_unique_sysids,
)
from gcs.link.config import shared_ports
from gcs.link.enums import MSG_ID, MavCmd
from gcs.link.samples import GpsGlobalOrigin, Heartbeat, HomePosition
from gcs.mission.machine import MissionMachine
from gcs.mission.plan import EXIT_ABORTED, Outcome, Phase

logger = logging.getLogger("gcs.fly")


class Flight:
    """One flight of the team (see the module docstring). Use `await Flight(setup, opts).run()`."""

    def __init__(self, setup: FlightSetup, options: FlyOptions,
                 status_factory: Callable[[Flight], Any] | None = None, *,
                 law_rows: LawRows | None = None, law_setup: FlightSetup | None = None) -> None:
        """`law_rows` and `law_setup` (an agent's flight, gcs/agent/): the law is built and
        run over `law_setup`'s team, of which `law_rows.own_rows` are this flight's vehicles."""
        self.setup = setup
        self.options = options
        team = setup.team
        self.team = team
        self.n = team.n
        self.ids = team.ids()
        self.period_s = 1.0 / setup.tick_rate_hz
        self.machine = MissionMachine(setup.plan, self.ids)
        # position mode (law "autopilot") runs no law: the one built here is never stepped
        position_mode = setup.mode == ControlMode.POSITION
        law_setup = setup if law_setup is None else law_setup
        self.law, rhohat, inertia_estimated = build_law(law_setup)
        warm_up(self.law, law_setup.team, self.period_s)
        if law_rows is not None:
            rhohat = rhohat[law_rows.own_rows]
        vehicles = team.vehicles
        fr = team.frame
        self.ties = TeamTies(TeamFrame(Geodetic(*fr.origin)),
                             [f"vehicle {v.id} (sysid {v.sysid})" for v in vehicles],
                             fr.vehicles == "shared", fr.max_origin_distance_m)
        self.compiled_after_ready: list[str] = []  # numba compiles while flying (run())
        self.scheduling: Scheduling | None = None  # what the OS gave (gcs fly sets it)
        # per vehicle, what flies it beyond its autopilot family (gcs fly --emulators: the
        # emulator's personality); for the records only
        self.vehicle_notes: dict[int, str] = {}
        self.links = [
            VehicleLinkConfig(vehicle_id=v.id, sysid=v.sysid, local_port=v.link.local_port,
                              remote_port=v.link.remote_port,
                              remote_host=v.link.remote_host or "127.0.0.1",
                              learn_remote=v.link.learn_remote,
                              link_timeout_s=team.fly.link_timeout_s,
                              timesync_period_s=team.fly.timesync_period_s,
                              silent_wait_s=setup.plan.connect_timeout_s)
            for v in vehicles
        ]
        check_unique_sysids(self.links)
        self.shared_ports = shared_ports(self.links)  # (host, port) -> the vehicles on it
        self.hot = HotTable(len(self.links))  # the team's hot telemetry, a row per link
        self.proxies: list[VehicleProxy] = []
        self._proxy_by_id: dict[int, VehicleProxy] = {}
        self.figures = Figures(
            flight_log_builder(setup, rhohat, inertia_estimated), TickStats(setup.tick_rate_hz),
            AgeStats(self.n), np.zeros(self.n, dtype=np.int64),
            # delay compensation (gcs/control/predict.py) and its measured error
            PredictionAudit(self.n) if team.fly.predict and not position_mode else None,
            VelocityConsistency(self.n, 0.0 if position_mode
                                else team.fly.velocity_from_position_s),
            AccelerationConsistency(self.n, 0.0 if position_mode
                                    else team.fly.acceleration_from_velocity_s))
        self.commander = Commander(self.machine, setup.requested_rates_hz,
                                   setup.plan.mode_timeout_s, self._proxy_by_id)
        self.setpoints = Setpoints(team, setup.mode, self.machine, self.ties, self.proxies,
                                   self.figures.limited_ticks)
        self.tick = Tick(setup, self.machine, self.law, self.ties, self.hot, self.proxies,
                         self.commander, self.setpoints, self.figures, law_rows)
        #: tasks that run beside the tick for the flight's lifetime, each given the event set
        #: when the flight is done (an agent's bus: its status, the supervisor's gates)
        self.companions: list[Callable[[asyncio.Event], Awaitable[None]]] = []
        #: sections added to the records (an agent's neighbour figures), read at the end
        self.report_more: Callable[[], dict[str, Any]] | None = None
        self._finished = asyncio.Event()
        self.tick_loop = TickLoop(self.machine, self.period_s, self.figures.ticks, self.tick.step,
                                  self._finished)
        self._tlog: TlogWriter | None = None  # the flight's, while it runs
        self._tg: asyncio.TaskGroup | None = None
        self._status_factory = status_factory
        # made last: its time is the flight's start (STATUSTEXT times in the report)
        self.records = Records(setup, options, self.machine, self.proxies, self.figures)

    # --- lifetime --------------------------------------------------------------------------------

    async def run(self) -> FlyResult:
        """Fly until the mission machine is done; returns when the records are written."""
        out = self.options.out_dir
        out.mkdir(parents=True, exist_ok=True)
        loop = asyncio.get_running_loop()
        with contextlib.ExitStack() as sync_stack:
            late = watch_late_compiles("gcs fly", logger)
            sync_stack.callback(late.close)
            self.compiled_after_ready = late.compiled
            tlog = sync_stack.enter_context(TlogWriter(out / TLOG_NAME))
            self._tlog = tlog
            sync_stack.callback(self._remove_signal_handlers, loop)
            self._install_signal_handlers(loop)
            async with contextlib.AsyncExitStack() as stack:
                # every link's port runs the hot path into the team's table (gcs.link.fastpath);
                # vehicles with the same GCS port share it (told apart by sysid)
                ports: dict[tuple[str, int], MavlinkPort] = {}
                for slot, cfg in enumerate(self.links):
                    where = (cfg.local_host, cfg.local_port)
                    port = ports.get(where) if where in self.shared_ports else None
                    if port is None:
                        try:
                            port = await stack.enter_async_context(MavlinkPort(
                                cfg.local_port, local_host=cfg.local_host, tlog=tlog,
                                table=self.hot, name=cfg.name if where not in self.shared_ports
                                else None))
                        except OSError as exc:  # nothing was sent yet: a setup error
                            raise FlightSetupError(
                                f"{cfg.name}: cannot listen on udp {cfg.local_host}:"
                                f"{cfg.local_port} (link.local_port): {exc.strerror or exc}; "
                                "another program or another vehicle of the team holds it"
                            ) from exc
                        ports[where] = port
                    proxy = await stack.enter_async_context(VehicleProxy(cfg, tlog=tlog,
                                                                         port=port, slot=slot))
                    self.proxies.append(proxy)
                    self._proxy_by_id[cfg.vehicle_id] = proxy
                self.tick.links_opened()
                logger.info("%s", self.setup.stability)
                try:
                    async with asyncio.TaskGroup() as tg:
                        self._tg = self.commander.tg = tg
                        tg.create_task(self.tick_loop.run(), name="control tick")
                        if not self.ties.complete:
                            tg.create_task(self._origins_loop(), name="origins")
                        for k, companion in enumerate(self.companions):
                            tg.create_task(companion(self._finished), name=f"companion {k}")
                        if self._status_factory is not None:
                            tg.create_task(self._status_factory(self).run(self._finished),
                                           name="status")
                        if self.options.abort_key:
                            stack.enter_context(self._abort_key(loop))
                except BaseException:
                    logger.exception("flight code failed; abort action to every vehicle")
                    await self._emergency_stop()
                    raise
        outcome = self.machine.outcome or Outcome(EXIT_ABORTED, "stopped without an outcome")
        # the links are closed: the records and figures are no timed work, and at SCHED_FIFO
        # they would take a core from the vehicles' simulators for seconds
        if leave_realtime():
            logger.info("flight over: normal scheduling for the records")
        return self.records.write(outcome, scheduling=self.scheduling, tlog=self._tlog,
                                  vehicle_notes=self.vehicle_notes,
                                  compiled_after_ready=self.compiled_after_ready,
                                  more=self.report_more() if self.report_more else None)

    def _install_signal_handlers(self, loop: asyncio.AbstractEventLoop) -> None:
        for sig, why in ((signal.SIGINT, "interrupted (Ctrl-C)"), (signal.SIGTERM, "terminated")):
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.add_signal_handler(sig, self.machine.request_abort, why)

    @staticmethod
    def _remove_signal_handlers(loop: asyncio.AbstractEventLoop) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.remove_signal_handler(sig)

    @contextlib.contextmanager
    def _abort_key(self, loop: asyncio.AbstractEventLoop):  # noqa: ANN202
        """On a terminal: 'q' or 'a' aborts (lands/holds per the team file)."""
        if not sys.stdin.isatty():
            yield
            return
        import termios
        import tty

        fd = sys.stdin.fileno()
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)

        def on_key() -> None:
            key = os.read(fd, 1)
            if key in (b"q", b"a", b"Q", b"A"):
                self.machine.request_abort("abort key pressed")

        loop.add_reader(fd, on_key)
        try:
            yield
        finally:
            loop.remove_reader(fd)
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)

    async def _emergency_stop(self) -> None:
        """Best effort after a failure of the flight code: abort action to every vehicle."""
        land = self.setup.plan.abort_action == FlyAction.LAND

        async def one(vehicle_id: int, p: VehicleProxy) -> None:
            profile = self.machine.profile(vehicle_id)
            with contextlib.suppress(Exception):
                if land:
                    await self.commander.land(p, profile, timeout_s=0.3, retries=2)
                else:
                    await self.commander.set_mode(p, profile, profile.hold, timeout_s=0.3,
                                                  retries=2)

        await asyncio.gather(*(one(self.ids[i], p) for i, p in enumerate(self.proxies)))

    async def _origins_loop(self) -> None:
        """Tie each vehicle's local frame to the team frame through its origin: GPS_GLOBAL_ORIGIN
        as it arrives (PX4 sends it once, just after boot), else asked for with REQUEST_MESSAGE
        (49) once a second, else (after two unanswered requests) HOME_POSITION's; until every
        vehicle is tied or the flight ends.
        A refused or unanswered request is retried (ArduPilot refuses until its EKF has an
        origin); the preflight waits up to MissionPlan.origin_timeout_s, then reports why."""
        asked = [-math.inf] * self.n
        requests = [0] * self.n
        loop = asyncio.get_running_loop()
        while not self.ties.complete and not self.machine.done:
            for i, p in enumerate(self.proxies):
                if self.ties.ties[i] is not None:
                    continue
                origin, source = None, ""
                try:
                    if (gpo := p.sample(GpsGlobalOrigin)) is not None:
                        origin, source = origin_from_gps_global_origin(gpo), "GPS_GLOBAL_ORIGIN"
                    elif (home := p.sample(HomePosition)) is not None and requests[i] >= 2:
                        # GPS_GLOBAL_ORIGIN is the origin itself: HOME_POSITION's only when two
                        # requests for it went unanswered
                        origin, source = origin_from_home_position(home), "HOME_POSITION"
                except ValueError as exc:
                    self.ties.refuse(i, f"malformed origin: {exc}")
                    continue
                if origin is not None:
                    line = self.ties.tie(i, origin, source)
                    logger.log(logging.INFO if self.ties.ties[i] is not None else logging.WARNING,
                               "%s", line)
                elif (self.machine.phase is not Phase.CONNECT and p.sample(Heartbeat) is not None
                      and loop.time() - asked[i] >= 1.0):  # asked once the team is connected
                    asked[i] = loop.time()
                    requests[i] += 1
                    self._tg.create_task(self._ask_origin(p), name=f"origin of {p.name}")
            await asyncio.sleep(0.1)

    @staticmethod
    async def _ask_origin(p: VehicleProxy) -> None:
        """REQUEST_MESSAGE GPS_GLOBAL_ORIGIN (49); the answer lands in the telemetry cache."""
        try:
            await p.commands.command_long(MavCmd.REQUEST_MESSAGE,
                                          (float(MSG_ID["GPS_GLOBAL_ORIGIN"]),),
                                          timeout_s=0.5, retries=0)
        except (CommandRejectedError, CommandTimeoutError, LinkClosedError) as exc:
            logger.debug("%s: origin request: %s", p.name, exc)


async def fly(team: TeamConfig, options: FlyOptions,
              status_factory: Callable[[Flight], Any] | None = None) -> FlyResult:
    """Fly `team` once; returns when every vehicle is landed/holding (or lost) and the records
    are written. Raises FlightSetupError before opening any link if the setup is invalid."""
    setup = prepare(team, options)
    return await Flight(setup, options, status_factory).run()


__all__ = ["Flight", "fly"]
