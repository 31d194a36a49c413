"""Composition root of `gcs fly`: links, the mission machine, the fixed-rate control tick, records.

One asyncio event loop owns everything through an `asyncio.TaskGroup`:

* one `VehicleProxy` per vehicle (codec + UDP endpoint + telemetry cache + acked commands),
* the control tick (`_tick_loop`): absolute deadlines t0 + k h (never `sleep(h)`, so it does not
  drift), lateness measured; each tick snapshots every vehicle's telemetry as received, steps the
  pure `MissionMachine`, runs the WHOLE team's law in one vectorised `TeamLaw.step`, and sends
  each streaming vehicle its setpoint,
* one task per command the machine asks for (its result goes back to the machine),
* the live status (gcs/status.py) and, on a terminal, the abort key.

Each vehicle is commanded through its autopilot's profile (gcs.mission.autopilots: PX4 OFFBOARD /
ArduPilot GUIDED_NOGPS, their hold, land and takeoff recipes), which the machine fixes at preflight
from the vehicle's HEARTBEAT; a team may mix autopilots.

Ctrl-C / SIGTERM / the abort key become `MissionMachine.request_abort`; the machine then lands or
holds every vehicle and keeps streaming to each until it has left offboard. If the flight code
itself fails, `_emergency_stop` still sends the abort action to every vehicle before the links
close. See docs/architecture.md and docs/gcs.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import copy
import dataclasses
import logging
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs import frames
from gcs.config import (
    AUTO_MODES,
    FLY_ACTIONS,
    FLY_CONTROL_MODES,
    FLY_MODES,
    POSITION_MODE,
    TORQUE_MODES,
    ConfigError,
    TeamConfig,
    check_go_to_start,
)
from gcs.control.formation import reference_velocity
from gcs.control.gains import GRAVITY_MPS2, LawGains
from gcs.control.law import SingularCommandError, TeamCommand, TeamLaw, TeamMeasurement
from gcs.control.position import phi
from gcs.control.slots import FormationSlots, SlotTargets
from gcs.flightlog import (
    AUTOPILOT_CONTROLLER,
    FlightLog,
    FlightLogBuilder,
    estimates_record,
    save_timeseries,
)
from gcs.fly.collector import PacedCollector
from gcs.fly.delay import DelayJudge, unmeasured_delay_lines
from gcs.fly.measure import (
    HOVER_MIN_SAMPLES,
    HOVER_RATE_HZ,
    HOVER_WINDOW_S,
    HoverEstimate,
    HoverThrust,
    TeamSample,
    command_heading_rad,
    desaturate_torque,
    drop_stale_neighbours,
    fresh_mask,
    level_rotations,
    limit_rate_command,
    normalised_thrust,
    normalised_torque,
    torque_max_nm,
)
from gcs.fly.origins import (
    TeamTies,
    origin_from_gps_global_origin,
    origin_from_home_position,
)
from gcs.fly.predict import PredictionAudit, horizons_s, predict, uplink_delay_s
from gcs.fly.sched import Scheduling
from gcs.fly.stats import (
    AgeStats,
    TickStats,
    clock_report,
    link_report,
    log_due,
    prediction_report,
    round_trip_report,
)
from gcs.fly.telemetry import StatusSlices, team_sample, vehicle_statuses
from gcs.fly.telemetry import warm_up as sample_warm_up
from gcs.geodesy import Geodetic, TeamFrame
from gcs.link import (
    CommandNotConfirmedError,
    CommandRejectedError,
    CommandTimeoutError,
    HotTable,
    LinkClosedError,
    MavlinkPort,
    SetpointError,
    TlogWriter,
    VehicleLinkConfig,
    VehicleProxy,
    check_unique_sysids,
    fastpath,
)
from gcs.link.config import shared_ports
from gcs.link.enums import MSG_ID, MavCmd, MavModeFlag
from gcs.link.proxy import TeamSetpoints
from gcs.metrics import formation_error, formation_error_m
from gcs.mission.autopilots import PROFILES, AutopilotProfile, ModeSpec, version_text
from gcs.mission.cascade import (
    AutopilotResponse,
    CascadeGains,
    cascade_margins,
    laplacian_eigenvalues,
    passes,
    verdict,
)
from gcs.mission.goto import GoToStartPlan
from gcs.mission.machine import (
    EXIT_ABORTED,
    Cmd,
    Command,
    CommandResult,
    MissionMachine,
    MissionPlan,
    NoteLevel,
    Outcome,
    Phase,
)
from gcs.mission.safety import SafetyRules
from gcs.mission.stability import (
    MIN_DECAY_PER_S,
    delays_ticks,
    describe_margins,
    torque_margins,
)
from gcs.report import build_report, write_report
from vehicle_emulator.latecompile import watch_late_compiles

logger = logging.getLogger(__name__)

REPORT_NAME = "report.json"
TIMESERIES_NAME = "timeseries.csv"
TLOG_NAME = "flight.tlog"
#: Streams that are not needed and cost CPU on both sides: switched off (0) or slowed down; and
#: the few the checks read that a vehicle streaming only what is asked for (PX4's MAVLink modes
#: without defaults, `vehicle-emu --streams requested`) would not send: SYS_STATUS (pre-arm).
OPTIONAL_RATES_HZ = {"ATTITUDE": 0.0, "ODOMETRY": 0.0, "GLOBAL_POSITION_INT": 5.0, "HEARTBEAT": 5.0,
                     "SYS_STATUS": 2.0}
MAX_POSITION_RATE_HZ = 100.0
#: EXTENDED_SYS_STATE (landed state: preflight, takeoff, stopping); ArduPilot sends it only when
#: asked with SET_MESSAGE_INTERVAL (it is in none of its stream groups).
LANDED_STATE_RATE_HZ = 5.0
#: The tick wakes this much before its deadline and blocks precisely for the rest (see _tick_loop).
WAKE_EARLY_S = 1.5e-3
#: The mission machine (checks, phase changes) runs at about this rate, on tick boundaries.
MACHINE_RATE_HZ = 20.0


class FlightSetupError(Exception):
    """The flight cannot start as configured (before any link is opened); one line."""


@dataclass(frozen=True, slots=True)
class FlyOptions:
    """Command-line overrides of the team file for one flight (None: the file's value)."""

    out_dir: Path
    mode: str | None = None
    law: str | None = None
    tick_rate_hz: float | None = None
    duration_s: float | None = None
    end_action: str | None = None
    figures: bool = True
    status: str = "auto"  # auto | rich | plain | off
    abort_key: bool = True
    connect_timeout_s: float | None = None


@dataclass(frozen=True, slots=True)
class FlightSetup:
    """Everything derived from the team file before flying (pure; see `prepare`)."""

    team: TeamConfig
    mode: str
    law: str
    tick_rate_hz: float
    gains: LawGains
    plan: MissionPlan
    requested_rates_hz: dict[str, float]
    log_every: int
    stability: str  # the discrete-time criterion, evaluated (for the log and the report)
    # rates/attitude: the criterion again at each link's measured delay, in preflight
    delay_judge: DelayJudge | None = None
    mode_choice: str = ""  # which mode is flown and why (resolve_mode)


@dataclass(frozen=True, slots=True)
class FlyResult:
    outcome: Outcome
    log: FlightLog | None
    out_dir: Path
    report: dict[str, Any] | None


def cascade_check(team: TeamConfig, mode: str, gains: LawGains,
                  rate_hz: float) -> tuple[str, dict[int, str], DelayJudge]:
    """The cascade criterion of `mode` for every autopilot gcs fly flies (gcs/mission/cascade.py).

    With `fly.response` the vehicles' loops are known: a failure raises FlightSetupError before
    anything is opened. Otherwise each autopilot's recorded default applies, and a failure is
    returned as a refusal for the vehicles of that autopilot (preflight, one line each).
    Returns (the evaluated criterion for the log, autopilot -> refusal, the same criterion for
    the delays preflight measures).
    """
    fly = team.fly
    eigenvalues = laplacian_eigenvalues(team.laplacian())
    cascade_gains = CascadeGains(gains.alpha_p, gains.c_p, gains.k_eps, gains.k_eps_yaw)
    explicit = _declared_response(team)
    lines, refusals = [], {}
    for profile in PROFILES.values():
        ok, line = verdict(mode, cascade_gains, explicit or profile.response, eigenvalues,
                           rate_hz, fly.link_delay_s,
                           "every vehicle" if explicit is not None else profile.name,
                           fly.predict)
        if not ok and explicit is not None:
            raise FlightSetupError(line)
        if not ok:
            refusals[profile.autopilot] = line
        lines.append(line)
        if explicit is not None:
            break  # one response for every vehicle
    judge = DelayJudge(mode, cascade_gains, eigenvalues, rate_hz, fly.link_delay_s, explicit,
                       fly.predict)
    return "\n".join(lines), refusals, judge


def _declared_response(team: TeamConfig) -> AutopilotResponse | None:
    """The vehicles' loops as the team file declares them (fly.response), else None."""
    r = team.fly.response
    return (None if r is None else
            AutopilotResponse(**dataclasses.asdict(r), source="the team file's fly.response"))


def _mode_gains(team: TeamConfig, mode: str) -> LawGains:
    """The law's gains as flown in `mode`: fly.<mode>'s over controller.gains."""
    mode_cfg, g = team.fly.mode(mode), team.controller.gains
    flown = {name: getattr(mode_cfg, name) for name in ("k_eps", "k_eps_yaw", "alpha_p", "c_p")
             if getattr(mode_cfg, name) is not None}
    return g._replace(
        alpha_eps=mode_cfg.alpha_eps if mode == "actuators" and mode_cfg.alpha_eps else g.alpha_eps,
        alpha_omega=(mode_cfg.alpha_omega if mode == "actuators" and mode_cfg.alpha_omega
                     else g.alpha_omega),
        alpha_rho=(mode_cfg.alpha_rho if mode == "actuators" and mode_cfg.alpha_rho
                   else g.alpha_rho),
        **flown,
    )


def resolve_mode(team: TeamConfig, requested: str | None,
                 tick_rate_hz: float | None = None) -> tuple[str, str]:
    """(the control mode to fly, one line saying why) for `--mode` (None: the file's fly.mode).

    `auto` flies the first of AUTO_MODES (rates, then attitude) whose loops pass the cascade
    criterion with the file's gains for that mode at fly.link_delay_s on every autopilot gcs fly
    flies (fly.response: on that response alone); rates comes first because where both pass it
    admits the stiffer position loop (docs/gcs.md, "Control modes"). actuators is never chosen:
    PX4 from 1.14 and ArduPilot ignore actuator setpoints, and the torque loop would run across
    the link. When neither passes, auto flies rates and preflight refuses the vehicles whose
    autopilot it fails on, naming gains that pass.
    """
    fly = team.fly
    mode = requested or fly.control_mode
    if mode != "auto":
        source = "--mode" if requested else "fly.mode"
        return mode, f"mode {mode} ({source})"
    eigenvalues = laplacian_eigenvalues(team.laplacian())
    declared = _declared_response(team)
    responses = ([("every vehicle", declared)] if declared is not None else
                 [(p.name, p.response) for p in PROFILES.values()])
    failed: dict[str, list[str]] = {}
    for mode in AUTO_MODES:
        g = _mode_gains(team, mode)
        rate = tick_rate_hz or fly.mode(mode).tick_rate_hz
        cg = CascadeGains(g.alpha_p, g.c_p, g.k_eps, g.k_eps_yaw)
        failed[mode] = [name for name, response in responses
                        if not passes(cascade_margins(mode, cg, response, eigenvalues, rate,
                                                      fly.link_delay_s, fly.predict))]
        if not failed[mode]:
            names = " and ".join(name for name, _ in responses)
            skipped = "".join(f"; {m} fails on {', '.join(failed[m])}" for m in AUTO_MODES
                              if failed.get(m))
            return mode, (f"mode {mode} (auto: the first of {', '.join(AUTO_MODES)} whose loops "
                          f"pass on {names} with fly.{mode}'s gains at link delay "
                          f"{1e3 * fly.link_delay_s:.0f} ms{skipped})")
    fails = "; ".join(f"{m} fails on {', '.join(failed[m])}" for m in AUTO_MODES)
    return AUTO_MODES[0], (f"mode {AUTO_MODES[0]} (auto: no mode passes on every autopilot "
                           f"with the file's gains at link delay {1e3 * fly.link_delay_s:.0f} ms: "
                           f"{fails}; preflight refuses the vehicles it fails on)")


def prepare(team: TeamConfig, options: FlyOptions) -> FlightSetup:
    """Resolve mode, law, rate and gains; check the discrete-time criterion (stability.py).

    Raises FlightSetupError naming the vehicle, the figure and the limit when a mode would not be
    stable at the rate it would run at.
    """
    fly = team.fly
    if options.mode is not None and options.mode not in FLY_MODES:
        raise FlightSetupError(f"mode {options.mode!r}: expected one of {FLY_MODES}")
    mode, mode_choice = resolve_mode(team, options.mode, options.tick_rate_hz)
    if mode not in FLY_CONTROL_MODES:
        raise FlightSetupError(f"mode {mode!r}: expected one of {FLY_CONTROL_MODES}")
    position = mode == POSITION_MODE
    if position and options.law is not None:
        raise FlightSetupError(f"--controller {options.law}: position mode runs no law (the "
                               "autopilots fly their formation slots); leave --controller out")
    # position mode: the autopilots' own position control flies; controller.law does not apply
    law = AUTOPILOT_CONTROLLER if position else options.law or team.controller.law
    if fly.initial_mass == "from_hover" and law == "adaptive":
        try:
            team = team.with_hover_masses()
        except ConfigError as exc:
            raise FlightSetupError(str(exc)) from None
    if law == "baseline":
        try:
            team.with_law("baseline")
        except ConfigError as exc:
            raise FlightSetupError(str(exc)) from None
    rate = options.tick_rate_hz or fly.tick_rate_hz(mode)
    if not 0.0 < rate <= 1000.0:
        raise FlightSetupError(f"tick rate {rate:g} Hz: expected 0 < rate <= 1000")
    ratio = rate / fly.log_rate_hz
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise FlightSetupError(
            f"tick rate {rate:g} Hz must be a multiple of fly.log_rate_hz {fly.log_rate_hz:g}")
    # position mode: the team file's gains only to build the (unused) law object
    gains = team.controller.gains if position else _mode_gains(team, mode)
    loop_refusals: dict[int, str] = {}
    judge = None
    if position:
        stability = ("position mode: no law runs on the ground station; each autopilot closes "
                     "every loop on board (no cascade or torque criterion applies)")
    elif mode == "actuators":
        # The criterion needs an inertia per vehicle: the nominal one where the file gives it,
        # else the initial estimate (never the plant's true value: the GCS does not know it).
        inertias = [
            v.nominal_inertia_kgm2 or v.estimates.inertia_kgm2
            for v in team.vehicles
        ]
        margins = torque_margins(team.ids(), inertias, gains.alpha_eps, gains.alpha_omega, rate)
        stability = (f"actuators mode at {rate:g} Hz, alpha_eps {gains.alpha_eps:g}, alpha_omega "
                     f"{gains.alpha_omega:g}:\n" + describe_margins(margins))
        bad = [m for m in margins if not m.ok()]
        if bad:
            worst = max(bad, key=lambda m: m.spectral_radius)
            raise FlightSetupError(
                f"actuators mode at {rate:g} Hz is not stable with alpha_eps {gains.alpha_eps:g}, "
                f"alpha_omega {gains.alpha_omega:g}: vehicle {worst.vehicle_id} axis {worst.axis} "
                f"(J {worst.inertia_kgm2:g} kg m^2) has spectral radius "
                f"{worst.spectral_radius:.3f} (decay {worst.decay_per_s:.3g} /s, need >= "
                f"{MIN_DECAY_PER_S:g} /s with 1-{delays_ticks(1.0 / rate)[-1]} ticks of delay); "
                f"set fly.actuators.alpha_eps/"
                f"alpha_omega or tick_rate_hz (docs/gcs.md)")
    else:  # rates, attitude: the law's loops over each autopilot's own (cascade.py)
        stability, loop_refusals, judge = cascade_check(team, mode, gains, rate)
    try:
        check_go_to_start(team)
    except ConfigError as exc:
        raise FlightSetupError(f"config error: {exc}") from None
    end_action = options.end_action or fly.end_action
    if end_action not in FLY_ACTIONS:
        raise FlightSetupError(f"end action {end_action!r}: expected one of {FLY_ACTIONS}")
    gf = fly.geofence
    # Attitude at the tick rate (the torque loop needs it fresh); position and IMU at most at
    # MAX_POSITION_RATE_HZ (the position loop is slow, and every message costs CPU on both ends).
    slow = min(rate, MAX_POSITION_RATE_HZ)
    required = {"ATTITUDE_QUATERNION": rate, "LOCAL_POSITION_NED": slow,
                "EXTENDED_SYS_STATE": LANDED_STATE_RATE_HZ}
    if team.controller.derivative.method == "model" and not position:
        required["HIGHRES_IMU"] = slow
    from_hover = law == "adaptive" and any(v.estimates.from_hover for v in team.vehicles)
    if from_hover:  # the autopilot's own hover thrust, read while it holds (docs/gcs.md)
        required["ATTITUDE_TARGET"] = HOVER_RATE_HZ
    rules = SafetyRules(
        max_tilt_rad=fly.max_tilt_rad, link_lost_after_s=fly.link_lost_after_s,
        max_data_age_s=fly.max_data_age_s,
        geofence_min_enu_m=gf.min_enu_m if gf else None,
        geofence_max_enu_m=gf.max_enu_m if gf else None,
        required_rates_hz=required, loop_refusals=loop_refusals,
    )
    plan = MissionPlan(
        duration_s=options.duration_s or team.mission.duration_s, rules=rules, control_mode=mode,
        start=fly.start,
        takeoff_altitude_m=fly.takeoff_altitude_m, end_action=end_action,
        abort_action=fly.abort_action, link_loss_action=fly.link_loss_action,
        connect_timeout_s=options.connect_timeout_s or fly.connect_timeout_s,
        takeoff_timeout_s=fly.takeoff_timeout_s,
        takeoff_tolerance_m=fly.takeoff_tolerance_m,
        land_timeout_s=fly.land_timeout_s,
        arm_timeout_s=fly.arm_timeout_s, arm_retry_s=fly.arm_retry_s,
        mode_timeout_s=fly.mode_timeout_s,
        formation_check_s=fly.formation_check.after_s,
        formation_max_error_m=fly.formation_check.max_error_m,
        formation_max_fraction=fly.formation_check.max_fraction,
        go_to_start=go_to_start_plan(team),
        **({"prime_s": HOVER_WINDOW_S + 0.5} if from_hover else {}),
    )
    return FlightSetup(team, mode, law, rate, gains, plan, required,
                       round(rate / fly.log_rate_hz), stability, judge, mode_choice)


def go_to_start_plan(team: TeamConfig) -> GoToStartPlan | None:
    """The go-to-start phase of the team file (`fly.go_to_start`, the vehicles' start positions
    `initial.position_enu_m` in the team frame); None when it is off."""
    g = team.fly.go_to_start
    if g.enabled == "false":
        return None
    starts = tuple((v.id, tuple(float(x) for x in v.initial.position_enu_m))
                   for v in team.vehicles)
    return GoToStartPlan(starts, g.enabled, g.tolerance_m, g.max_speed_mps, g.settle_s,
                         g.timeout_s, g.cruise_speed_mps)


def true_mass_kg(team: TeamConfig, t_s: float) -> np.ndarray:
    """The team file's plant masses with its mass-drop faults applied at formation time t_s
    (NaN without a plant). For the records only: the controller never sees it."""
    out = np.array([v.plant.mass_kg if v.plant else math.nan for v in team.vehicles])
    for f in team.faults:
        if f.kind == "mass_drop" and t_s >= f.at_s:
            out[team.index_of(f.vehicle)] *= 1.0 - f.fraction
    return out


class Flight:
    """One flight of the team (see the module docstring). Use `await Flight(setup, opts).run()`."""

    def __init__(self, setup: FlightSetup, options: FlyOptions,
                 status_factory: Callable[[Flight], Any] | None = None) -> None:
        self.setup = setup
        self.options = options
        team = setup.team
        self.team = team
        self.n = team.n
        self.ids = team.ids()
        self.period_s = 1.0 / setup.tick_rate_hz
        self.machine = MissionMachine(setup.plan, self.ids)
        # position mode (law "autopilot") runs no law: the one built here is never stepped
        self.position_mode = setup.mode == POSITION_MODE
        baseline = setup.law == "baseline"
        adaptive = setup.law == "adaptive"
        vehicles = team.vehicles
        nominal = team.nominal_masses_kg() if baseline else None
        rhohat = np.array([v.baseline_inertia_kgm2 if baseline else v.estimates.inertia_kgm2
                           for v in vehicles], dtype=float)
        d = team.controller.derivative
        # rhohat acts only through the torque (26): in rates and attitude mode it is held
        inertia_estimated = adaptive and setup.mode in TORQUE_MODES
        self.law = TeamLaw(
            setup.gains, team.adjacency(), team.offsets_enu_m(), team.initial_mhat(), rhohat,
            nominal_mass_kg=nominal, adaptive=not baseline, derivative=d.method,
            levant_lipschitz=d.levant_lipschitz, levant_substep_s=d.levant_substep_s,
            estimate_inertia=inertia_estimated,
        )
        self.law.inertia_step_max_s = self.period_s
        self.ref_arrays = tuple(np.ascontiguousarray(a, dtype=float)
                                for a in team.reference_velocity.as_arrays())
        self._offsets_m = np.ascontiguousarray(team.offsets_enu_m(), dtype=float)
        self._warm_up(team, setup, rhohat, nominal)
        self.max_thrust_n = np.array([v.airframe.max_thrust_n for v in vehicles])
        self.arm_m = np.array([v.airframe.arm_length_m for v in vehicles])
        self.anti_torque_m = np.array([v.airframe.anti_torque_m for v in vehicles])
        self.rotor_max_n = np.array([v.airframe.rotor_thrust_max_n for v in vehicles])
        self.torque_max = torque_max_nm(self.arm_m, self.anti_torque_m, self.rotor_max_n)
        self.max_rate_radps = team.fly.rates.max_rate_radps
        self.hover = HoverThrust(self.n)
        self._from_hover = adaptive and any(v.estimates.from_hover for v in vehicles)
        self.slots: FormationSlots | None = None  # position mode: fixed at the formation start
        self._slot_yaw_ned = np.zeros(self.n)  # position mode: the heading each slot holds
        fr = team.frame
        self.ties = TeamTies(TeamFrame(Geodetic(*fr.origin)),
                             [f"vehicle {v.id} (sysid {v.sysid})" for v in vehicles],
                             fr.vehicles == "shared", fr.max_origin_distance_m)
        self._tie_arrays = (None if fr.vehicles == "shared"
                            else (self.ties.offsets_enu_m, self.ties.rotations))
        self.hover_estimates: dict[int, HoverEstimate] = {}
        self.compiled_after_ready: list[str] = []  # numba compiles while flying (run())
        self.scheduling: Scheduling | None = None  # what the OS gave (gcs fly sets it)
        # per vehicle, what flies it beyond its autopilot family (gcs fly --emulators: the
        # emulator's personality); for the records only
        self.vehicle_notes: dict[int, str] = {}
        self.max_yaw_rate_radps = team.fly.rates.max_yaw_rate_radps
        self.limited_ticks = np.zeros(self.n, dtype=np.int64)  # rate or torque limit applied
        # Before the formation starts (PRIME), vehicles get level, zero-rate setpoints at the
        # law's own initial mass estimate times g (what the law itself would ask at rest).
        kappa0 = (np.asarray(nominal, dtype=float) if baseline
                  else setup.gains.alpha_m * team.initial_mhat() / 2.0)
        self.prime_thrust_norm = normalised_thrust(kappa0 * GRAVITY_MPS2, self.max_thrust_n)
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
        self._clocks_in_table = False  # every proxy's clock filter writes its line into hot
        self._team_setpoints: TeamSetpoints | None = None  # once the proxies are open
        self._batchable = np.zeros(0, dtype=bool)  # per link: rates go in the team's batch
        # the rows of the last streaming set (the set, as a list, as an array)
        self._streaming_rows: tuple[frozenset[int] | None, list[int], np.ndarray] = (
            None, [], np.zeros(0, dtype=np.intp))
        self.proxies: list[VehicleProxy] = []
        self._proxy_by_id: dict[int, VehicleProxy] = {}
        self.builder = FlightLogBuilder(
            vehicle_ids=self.ids, sysids=team.sysids(), offsets_enu_m=team.offsets_enu_m(),
            source="fly", controller=setup.law, team=team.source_path, name=team.name,
            extra={"mode": setup.mode, "mode_choice": setup.mode_choice,
                   "tick_rate_hz": setup.tick_rate_hz,
                   "derivative": None if self.position_mode else d.method,
                   "gains": None if self.position_mode else setup.gains._asdict(),
                   "stability": setup.stability,
                   "estimates": (estimates_record(  # no law, nothing estimated
                       mass_from=["none"] * self.n, inertia_from="none", inertia_kgm2=None,
                       inertia_estimated=False) if self.position_mode else estimates_record(
                       mass_from=[("hover" if v.estimates.from_hover else "team") if adaptive
                                  else "nominal" for v in vehicles],
                       inertia_from="team" if adaptive else "nominal",
                       inertia_kgm2=rhohat, inertia_estimated=inertia_estimated))},
        )
        self.ticks = TickStats(setup.tick_rate_hz)
        self.ages = AgeStats(self.n)
        # delay compensation (gcs/fly/predict.py) and its measured error
        self.audit = (PredictionAudit(self.n) if team.fly.predict and not self.position_mode
                      else None)
        self._tlog: TlogWriter | None = None  # the flight's, while it runs
        self.machine_every = max(1, round(setup.tick_rate_hz / MACHINE_RATE_HZ))
        self._status_slices = StatusSlices(team.n, self.machine_every)  # the mission's statuses
        self.last_sample: TeamSample | None = None
        self.last_command: TeamCommand | None = None
        self.formation_error_m = math.nan
        self.formation_t_s: float | None = None
        self._k0: int | None = None
        self._next_log_k = 0  # the tick the flight log's next sample is due at (log_due)
        self._last_law_k: int | None = None
        self._tg: asyncio.TaskGroup | None = None
        self._finished = asyncio.Event()
        self._status_factory = status_factory
        self._setpoint_errors = 0
        self._notes_logged = 0
        self._t0_s = time.monotonic()  # the proxies' clock; STATUSTEXT times in the report
        self._goto_yaw_ned: dict[int, float] = {}  # heading held while going to start [rad]
        self._start_error_m: dict[int, float] = {}  # |p(0) - start| at the formation start

    def _warm_up(self, team: TeamConfig, setup: FlightSetup, rhohat: np.ndarray,
                 nominal: np.ndarray | None) -> None:
        """Compile (or load from numba's cache) every kernel the flight runs, on throwaway
        copies: the law's, the prediction audit's, the team sample's and the formation error's
        in the tick, the error series' of the records at the end. Compiled in the first
        formation tick instead (a new machine's first flight), the audit's stalled it for 0.5 s
        and more on a loaded machine: every link then read as lost, and the formation stopped
        at its start."""
        scratch = copy.deepcopy(self.law)
        n = team.n
        rotation = np.tile(np.eye(3), (n, 1, 1))
        meas = TeamSample(
            np.ascontiguousarray(team.initial_positions_enu_m(), dtype=float), np.zeros((n, 3)),
            np.zeros((n, 3)), rotation, np.zeros((n, 3)), np.zeros(n), np.zeros(n),
            np.ones(n, dtype=bool), np.zeros(n), np.zeros(n), np.zeros(n),
            np.zeros(n)).measurement()
        ref = reference_velocity(0.0, *self.ref_arrays)
        fresh = np.ones(n, dtype=bool)
        for _ in range(2):
            drop_stale_neighbours(scratch.graph, fresh, scratch.active_graph.weight)
            scratch.step(meas, ref, self.period_s)
        formation_error_m(meas.position_m, self._offsets_m)
        formation_error(meas.position_m[None], self._offsets_m)  # the records' series
        audit = PredictionAudit(n)
        taken = np.zeros(n)
        audit.record(0.0, meas, meas, taken)
        audit.observe(meas.position_m, meas.velocity_mps, taken, meas.rotation, meas.omega_radps,
                      taken)
        fastpath.warm_up()
        sample_warm_up()

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
                self._clocks_in_table = all(p.slot == i for i, p in enumerate(self.proxies))
                logger.info("%s", self.setup.stability)
                try:
                    async with asyncio.TaskGroup() as tg:
                        self._tg = tg
                        tg.create_task(self._tick_loop(), name="control tick")
                        if not self.ties.complete:
                            tg.create_task(self._origins_loop(), name="origins")
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
        return self._write_records(outcome)

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
        land = self.setup.plan.abort_action == "land"

        async def one(vehicle_id: int, p: VehicleProxy) -> None:
            profile = self.machine.profile(vehicle_id)
            with contextlib.suppress(Exception):
                if land:
                    await self._land(p, profile, timeout_s=0.3, retries=2)
                else:
                    await self._set_mode(p, profile, profile.hold, timeout_s=0.3, retries=2)

        await asyncio.gather(*(one(self.ids[i], p) for i, p in enumerate(self.proxies)))

    # --- commands --------------------------------------------------------------------------------

    def _dispatch(self, commands: Sequence[Command]) -> None:
        assert self._tg is not None
        for c in commands:
            self._tg.create_task(self._execute(c), name=f"vehicle {c.vehicle_id} {c.cmd.value}")

    async def _execute(self, c: Command) -> None:
        p = self._proxy_by_id[c.vehicle_id]
        profile = self.machine.profile(c.vehicle_id)
        ok, detail, result, text = True, "", "", ""
        values: list[tuple[str, float]] = []
        try:
            if c.cmd is Cmd.CONFIGURE:
                for kind, hz in self.setup.requested_rates_hz.items():
                    await p.set_message_interval(MSG_ID[kind], hz)
                for kind, hz in OPTIONAL_RATES_HZ.items():
                    await p.set_message_interval(MSG_ID[kind], hz, check=False)
            elif c.cmd is Cmd.READ_PARAMS:
                for name in c.names:
                    values.append((name, await p.param_read(name)))
                detail = ", ".join(f"{name} = {value:g}" for name, value in values)
            elif c.cmd is Cmd.IDENTIFY:
                word = await p.autopilot_version()
                values.append(("flight_sw_version", float(word)))
                detail = f"{profile.name} {version_text(word)}"
            elif c.cmd is Cmd.ARM_MODE:
                await self._set_mode(p, profile, profile.arm_mode, confirm=self._mode_timeout_s)
            elif c.cmd is Cmd.ARM:
                await self._arm(p, profile, self._mode_timeout_s)
            elif c.cmd is Cmd.DISARM:
                await p.disarm()
            elif c.cmd is Cmd.TAKEOFF:
                await p.takeoff(self._takeoff_amsl_m(p, c.altitude_m)
                                if profile.takeoff_altitude_amsl else c.altitude_m)
            elif c.cmd is Cmd.OFFBOARD:
                await self._set_mode(p, profile, self.machine.offboard_mode(c.vehicle_id),
                                     confirm=self._mode_timeout_s)
            elif c.cmd is Cmd.POSITION_MODE:
                await self._set_mode(p, profile, profile.position_mode,
                                     confirm=self._mode_timeout_s)
            elif c.cmd is Cmd.HOLD:
                await self._set_mode(p, profile, profile.hold, confirm=self._mode_timeout_s)
            elif c.cmd is Cmd.LAND:
                await self._land(p, profile, confirm=self._mode_timeout_s)
        except CommandRejectedError as exc:
            ok, detail, result, text = False, str(exc), exc.result.name, exc.text
        except CommandNotConfirmedError as exc:
            ok, detail, result, text = False, str(exc), "NOT_CONFIRMED", exc.text
        except (CommandTimeoutError, LinkClosedError, TimeoutError) as exc:
            ok, detail, result = False, str(exc), "TIMEOUT"
        logger.log(logging.INFO if ok else logging.WARNING, "vehicle %d: %s %s%s", c.vehicle_id,
                   c.cmd.value, "ok" if ok else "failed", f": {detail}" if detail else "")
        self._dispatch(self.machine.on_result(
            CommandResult(c.vehicle_id, c.cmd, ok, detail, tuple(values) if ok else (),
                          result, text)))

    @property
    def _mode_timeout_s(self) -> float:
        return self.setup.plan.mode_timeout_s

    @staticmethod
    def _mode_params(p: VehicleProxy, profile: AutopilotProfile, mode: ModeSpec) -> list[float]:
        """DO_SET_MODE params as the vehicle's autopilot encodes `mode` (PX4: +128 when armed,
        as MAVSDK sends it)."""
        if profile.family == "ardupilot":
            return [float(MavModeFlag.CUSTOM_MODE_ENABLED), mode.number]
        armed = p.state().armed
        base = MavModeFlag.CUSTOM_MODE_ENABLED | (MavModeFlag.SAFETY_ARMED if armed else 0)
        return [float(base), mode.number, mode.sub]

    @staticmethod
    def _reported(profile: AutopilotProfile) -> Callable[[Any], str]:
        """What a HEARTBEAT says, for messages: 'AUTO_LOITER, disarmed'."""
        def text(hb: Any) -> str:
            if hb is None:
                return "nothing (no HEARTBEAT yet)"
            armed = "armed" if int(hb.base_mode) & MavModeFlag.SAFETY_ARMED else "disarmed"
            return f"{profile.mode_name(int(hb.custom_mode))}, {armed}"
        return text

    @classmethod
    async def _set_mode(cls, p: VehicleProxy, profile: AutopilotProfile, mode: ModeSpec, *,
                        confirm: float | None = None, timeout_s: float = 0.5,
                        retries: int = 2) -> None:
        """DO_SET_MODE as the vehicle's autopilot encodes `mode`. With `confirm` (seconds):
        returns when a HEARTBEAT after the ACK shows the mode, every ACK read (a later refusal
        wins); raises CommandRejectedError / CommandNotConfirmedError / CommandTimeoutError
        naming the vehicle, the mode asked, the mode reported and the ACKs. Without: returns
        when the first ACK accepts it (the emergency stop's best effort)."""
        params = cls._mode_params(p, profile, mode)
        if confirm is None:
            await p.command_long(MavCmd.DO_SET_MODE, params, timeout_s=timeout_s,
                                 retries=retries)
            return
        want = mode.custom_mode(profile.family)
        await p.command_confirmed(
            MavCmd.DO_SET_MODE, params, want=f"mode {mode.name}",
            shows=lambda hb: int(hb.custom_mode) == want, reported=cls._reported(profile),
            timeout_s=confirm, ack_timeout_s=timeout_s, retries=retries)

    @classmethod
    async def _arm(cls, p: VehicleProxy, profile: AutopilotProfile, confirm: float) -> None:
        """COMPONENT_ARM_DISARM 1 (never forced); returns when HEARTBEAT shows armed."""
        await p.command_confirmed(
            MavCmd.COMPONENT_ARM_DISARM, [1.0, 0.0], want="armed",
            shows=lambda hb: bool(int(hb.base_mode) & MavModeFlag.SAFETY_ARMED),
            reported=cls._reported(profile), timeout_s=confirm)

    @classmethod
    async def _land(cls, p: VehicleProxy, profile: AutopilotProfile, *,
                    confirm: float | None = None, timeout_s: float = 0.5,
                    retries: int = 2) -> None:
        """The profile's land: its LAND mode (ArduPilot, confirmed with `confirm`) or
        MAV_CMD_NAV_LAND (PX4); returns when accepted, not when landed."""
        if profile.land is not None:
            await cls._set_mode(p, profile, profile.land, confirm=confirm, timeout_s=timeout_s,
                                retries=retries)
        else:
            await p.land(timeout_s=timeout_s, retries=retries)

    @staticmethod
    def _takeoff_amsl_m(p: VehicleProxy, altitude_m: float) -> float:
        """PX4 NAV_TAKEOFF wants AMSL: home AMSL (GLOBAL_POSITION_INT alt - relative_alt) + alt;
        NaN (the autopilot's MIS_TAKEOFF_ALT) when the vehicle sent no global position."""
        gpi = p.latest("GLOBAL_POSITION_INT")
        if gpi is None:
            return math.nan
        return (gpi.msg.alt - gpi.msg.relative_alt) * 1e-3 + altitude_m

    # --- the tick --------------------------------------------------------------------------------

    async def _tick_loop(self) -> None:
        """Fixed-rate tick on absolute deadlines t_start + k h; lateness recorded; a tick more
        than one period late is skipped (counted), never run twice."""
        loop = asyncio.get_running_loop()
        h = self.period_s
        margin = min(WAKE_EARLY_S, 0.25 * h)
        t_start = loop.time()
        k = 0
        try:
            # garbage collection between ticks, never in one (gcs/fly/collector.py)
            with PacedCollector() as collector:
                while not self.machine.done:
                    deadline = t_start + k * h
                    # asyncio's timers wake on a millisecond grid and after the I/O callbacks that
                    # are ready: wake `margin` early (telemetry handled meanwhile), then block for
                    # the sub-millisecond rest (time.sleep is precise and uses no CPU).
                    wait = deadline - loop.time() - margin
                    if wait > 0:
                        await asyncio.sleep(wait)
                    else:
                        await asyncio.sleep(0)  # let the telemetry callbacks run every tick
                    rest = deadline - loop.time()
                    if rest > 0:
                        time.sleep(rest)
                    started = loop.time()
                    behind = int((started - deadline) / h)
                    if behind >= 1:  # missed whole periods: jump to the newest deadline
                        if self.machine.phase is Phase.FORMATION:
                            self._stalled(behind, deadline)
                        k += behind
                        deadline = t_start + k * h
                    self._tick(k, deadline, started)
                    if self.machine.phase is Phase.FORMATION:  # the tick statistics of the report
                        self.ticks.record(started - deadline, loop.time() - started)
                    k += 1
                    collector.after_tick(t_start + k * h - loop.time(),
                                         bool(self.machine.streaming))
        finally:
            self._finished.set()

    def _stalled(self, periods: int, deadline_s: float) -> None:
        """Count the skipped ticks; a stall (gcs.fly.stats.STALL_S or longer) is logged: the
        vehicles flew it on their last setpoints."""
        t_s = self.machine.formation_time_s(deadline_s)
        t_s = math.nan if t_s is None else t_s
        gap_s = self.ticks.skip(periods, t_s)
        if gap_s is not None:
            logger.warning("tick: the ground station stopped for %.0f ms at t = %.2f s (%d ticks "
                           "skipped): the vehicles held their last setpoints meanwhile",
                           1e3 * gap_s, t_s, periods)

    def _tick(self, k: int, deadline_s: float, now_s: float) -> None:
        sample = team_sample(self.proxies, now_s, self.last_sample, self._tie_arrays, self.hot)
        self.last_sample = sample
        m = self.machine
        rows = self._status_slices.rows(k)
        if rows is None or rows:
            want_rates = (tuple(self.setup.plan.rules.required_rates_hz)
                          if m.phase in (Phase.CONNECT, Phase.PREFLIGHT) else ())
            judge = self.setup.delay_judge if m.phase is Phase.PREFLIGHT else None
            self._status_slices.store(rows, vehicle_statuses(
                self.proxies, self.ids, sample, want_rates, self.ties, judge, self.hot, rows=rows))
        if self._status_slices.due(k):
            self._dispatch(m.on_tick(deadline_s, self._status_slices.latest(),
                                     self.formation_error_m))
            self._log_notes()
            self._send_position_targets(sample)
        streaming = m.streaming
        if m.phase is Phase.PRIME and self._from_hover:
            self._record_hover_thrust()
        if m.law_active and (streaming or m.phase is Phase.FORMATION) and self.position_mode:
            self._fly_slots(k, sample, streaming)
        elif m.law_active and (streaming or m.phase is Phase.FORMATION):
            command = self._run_law(k, sample, now_s)
            if command is not None:
                self._send(command, streaming)
        elif m.phase is Phase.PRIME and self.position_mode:
            self._prime_slots(sample, streaming)
        elif m.phase is Phase.PRIME:
            # level and still: zero rates or torque; in attitude mode, level at the heading
            level = (self.ties.rotations_to_local(level_rotations(sample.rotation))
                     if self.setup.mode == "attitude" else np.zeros((self.n, 3)))
            self._send_vectors(level, np.asarray(self.prime_thrust_norm, dtype=float),
                               streaming)

    def _send_position_targets(self, sample: TeamSample) -> None:
        """Go to start: each vehicle the machine names gets its team-frame target and the
        target's velocity as feed-forward (`_send_position_target`), and the heading it had
        when it first got one (so it does not yaw)."""
        targets = self.machine.position_targets
        if not targets:
            return
        hold = None
        for i in range(self.n):
            vid = self.ids[i]
            if vid not in targets or self.ties.ties[i] is None:
                continue
            if vid not in self._goto_yaw_ned:
                if hold is None:
                    hold = self._yaw_ned(sample, "hold")
                self._goto_yaw_ned[vid] = float(hold[i])
            position, velocity = targets[vid]
            self._send_position_target(i, position, velocity, self._goto_yaw_ned[vid])

    def _send_position_target(self, i: int, position_enu_m: Any, velocity_enu_mps: Any,
                              yaw_ned_rad: float, acceleration_enu_mps2: Any = None) -> None:
        """SET_POSITION_TARGET_LOCAL_NED to vehicle i: a team-frame target in its own local frame
        (p_local = R_i^T (p_team - o_i), ENU -> NED), velocity (and acceleration) feed-forward
        turned the same way (R_i^T v_team); a setpoint the link refuses stops the flight."""
        tie = self.ties.ties[i]
        assert tie is not None  # preflight refuses an untied vehicle
        ned = frames.ned_from_enu(tie.local_from_team(position_enu_m))
        v_ned = frames.ned_from_enu(tie.vectors_local_from_team(velocity_enu_mps))
        a_ned = (None if acceleration_enu_mps2 is None
                 else frames.ned_from_enu(tie.vectors_local_from_team(acceleration_enu_mps2)))
        try:
            self.proxies[i].send_position_target(ned, v_ned, yaw_ned_rad, a_ned)
        except SetpointError as exc:
            self._setpoint_errors += 1
            self.machine.request_abort(str(exc), operator=False)

    def _yaw_ned(self, sample: TeamSample, heading: str | float) -> np.ndarray:
        """(n,) the yaw of a position setpoint [rad, from north, clockwise] in each vehicle's
        local frame for a `fly.heading` policy: 'hold' its heading now, 'paper' east, a number
        that compass heading (gcs.fly.measure.command_heading_rad)."""
        yaw_enu = command_heading_rad(heading, self.ties.rotations_to_local(sample.rotation))
        return np.remainder(np.pi / 2.0 - yaw_enu + np.pi, 2.0 * np.pi) - np.pi

    # --- position mode: the formation slots (gcs/control/slots.py) ----------------------------

    def _fly_slots(self, k: int, sample: TeamSample, streaming: frozenset[int]) -> None:
        """Position mode from the formation start: c(0) fixed from the team's positions at its
        first tick, then every streaming vehicle gets its slot c(t) + theta_i, v_r(t), v_r'(t)
        and its heading (fly.heading); records as the law's, with no law figures."""
        if self._k0 is None:
            self._start_formation(k, sample)
            try:
                self.slots = FormationSlots.start(sample.position_m, self._offsets_m,
                                                  self.ref_arrays)
            except ValueError as exc:
                self.machine.request_abort(f"t = 0 s: {exc}", operator=False)
                return
            self._slot_yaw_ned = self._yaw_ned(sample, self.team.fly.heading)
        if self.slots is None:  # the start failed: the flight is stopping, the failsafes act
            return
        t = (k - self._k0) * self.period_s
        targets = self.slots.at(t)
        self.formation_t_s = t
        log, self._next_log_k = log_due(k, self._k0, self.setup.log_every, self._next_log_k)
        if self.machine.phase is Phase.FORMATION:
            fresh = fresh_mask(sample, self.team.fly.stale_after_s)
            self.ages.record(sample.delay_s, sample.age_s, fresh, np.zeros(self.n, dtype=np.int64))
            if log:
                self._log(t, sample, targets.velocity_enu_mps, None)
        self._send_slots(targets, self._slot_yaw_ned, streaming)

    def _prime_slots(self, sample: TeamSample, streaming: frozenset[int]) -> None:
        """Position mode's PRIME: the slots of a formation starting now (no vehicle acts on them
        in its hold mode), so that PX4 has a recent setpoint when OFFBOARD is commanded."""
        try:
            targets = FormationSlots.start(sample.position_m, self._offsets_m,
                                           self.ref_arrays).at(0.0)
        except ValueError as exc:
            self.machine.request_abort(f"prime: {exc}", operator=False)
            return
        self._send_slots(targets, self._yaw_ned(sample, self.team.fly.heading), streaming)

    def _send_slots(self, targets: SlotTargets, yaw_ned_rad: np.ndarray,
                    streaming: frozenset[int]) -> None:
        for i in range(self.n):
            if self.ids[i] in streaming:
                self._send_position_target(i, targets.position_enu_m[i], targets.velocity_enu_mps,
                                           float(yaw_ned_rad[i]), targets.acceleration_enu_mps2)

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
                    if (gpo := p.latest("GPS_GLOBAL_ORIGIN")) is not None:
                        origin, source = origin_from_gps_global_origin(gpo.msg), "GPS_GLOBAL_ORIGIN"
                    elif (home := p.latest("HOME_POSITION")) is not None and requests[i] >= 2:
                        # GPS_GLOBAL_ORIGIN is the origin itself: HOME_POSITION's only when two
                        # requests for it went unanswered
                        origin, source = origin_from_home_position(home.msg), "HOME_POSITION"
                except ValueError as exc:
                    self.ties.refuse(i, f"malformed origin: {exc}")
                    continue
                if origin is not None:
                    line = self.ties.tie(i, origin, source)
                    logger.log(logging.INFO if self.ties.ties[i] is not None else logging.WARNING,
                               "%s", line)
                elif (self.machine.phase is not Phase.CONNECT and p.latest("HEARTBEAT") is not None
                      and loop.time() - asked[i] >= 1.0):  # asked once the team is connected
                    asked[i] = loop.time()
                    requests[i] += 1
                    self._tg.create_task(self._ask_origin(p), name=f"origin of {p.name}")
            await asyncio.sleep(0.1)

    @staticmethod
    async def _ask_origin(p: VehicleProxy) -> None:
        """REQUEST_MESSAGE GPS_GLOBAL_ORIGIN (49); the answer lands in the telemetry cache."""
        try:
            await p.command_long(MavCmd.REQUEST_MESSAGE, (float(MSG_ID["GPS_GLOBAL_ORIGIN"]),),
                                 timeout_s=0.5, retries=0)
        except (CommandRejectedError, CommandTimeoutError, LinkClosedError) as exc:
            logger.debug("%s: origin request: %s", p.name, exc)

    def _log_unmeasured_delays(self) -> None:
        """At the law's start: name the links whose delay no TIMESYNC round trip measured."""
        fly = self.team.fly
        for line in unmeasured_delay_lines(
                [(p.name, p.round_trips_s().size, p.stats().proxy.timesync_sent)
                 for p in self.proxies], fly.timesync_period_s, fly.link_delay_s):
            logger.warning("%s", line)

    def _record_hover_thrust(self) -> None:
        """PRIME: the vehicles hold on their own; keep the thrust they report (from_hover)."""
        hot = self.hot
        for i, (v, p) in enumerate(zip(self.team.vehicles, self.proxies, strict=True)):
            if not v.estimates.from_hover:
                continue
            if p.slot == i and hot.count[i, fastpath.ATTITUDE_TARGET] > 0:  # no decode per tick
                self.hover.add(i, float(hot.rx_s[i, fastpath.ATTITUDE_TARGET]),
                               float(hot.misc[i, fastpath.TARGET_THRUST]))
            elif (at := p.latest("ATTITUDE_TARGET")) is not None:
                self.hover.add(i, at.rx_time_s, float(at.msg.thrust))

    def _initial_mass_from_hover(self, sample: TeamSample, now_s: float) -> bool:
        """At the formation start: mhat_i(0) from the hover of each `mhat: from_hover` vehicle,
        checked against Proposition 2; False (and the flight stops) when one cannot be taken
        or fails the check."""
        if self.setup.law != "adaptive":
            return True
        g = self.setup.gains
        phi0_all = phi(np.ascontiguousarray(sample.velocity_mps), g.sigma_a)  # the law's (23)
        for i, v in enumerate(self.team.vehicles):
            if not v.estimates.from_hover:
                continue
            name = f"vehicle {v.id} (sysid {v.sysid})"
            phi0 = float(phi0_all[i])
            est = self.hover.estimate(i, now_s, v.airframe.max_thrust_n, g.alpha_m, phi0,
                                      v.mass_bound_kg)
            if est is None:
                self.machine.request_abort(
                    f"{name}: no hover thrust to take mhat(0) from (fewer than "
                    f"{HOVER_MIN_SAMPLES} ATTITUDE_TARGET in the {HOVER_WINDOW_S:g} s before the "
                    "formation start)", operator=False)
                return False
            self.hover_estimates[v.id] = est
            bound = ("no mass_bound_kg" if est.least_mhat0 is None else
                     f"Proposition 2: mhat(0) >= (phi(0) - 1) mbar / alpha_m = "
                     f"{est.least_mhat0:.4g} {'holds' if est.proposition2_holds else 'FAILS'}")
            logger.info("%s: hover thrust %.4f (%d samples) -> %.4g kg, mhat(0) %.4g; %s", name,
                        est.thrust_norm, est.samples, est.mass_kg, est.mhat0, bound)
            if not est.proposition2_holds:
                self.machine.request_abort(
                    f"{name}: mhat(0) {est.mhat0:.4g} from the hover ({est.mass_kg:.4g} kg) is "
                    f"below Proposition 2's {est.least_mhat0:.4g} (mass_bound_kg "
                    f"{v.mass_bound_kg:g})", operator=False)
                return False
            self.law.mhat[i] = est.mhat0
        return True

    def _log_notes(self) -> None:
        """Log the mission's new notes at their level (the outcome itself is printed by the
        command line; a stop before the formation's end is a warning, the normal end is not)."""
        m = self.machine
        for text, level in zip(m.notes[self._notes_logged:], m.note_levels[self._notes_logged:],
                               strict=True):
            logger.log(logging.WARNING if level is NoteLevel.WARNING else logging.INFO,
                       "mission: %s", text)
        self._notes_logged = len(m.notes)

    def _start_formation(self, k: int, sample: TeamSample) -> None:
        """The formation's first tick k (t = 0): each go-to-start vehicle's distance from its
        start position then (the records)."""
        self._k0 = self._next_log_k = k
        for vid, r in self.machine.goto_results.items():
            i = self.team.index_of(vid)
            self._start_error_m[vid] = float(np.linalg.norm(
                sample.position_m[i] - np.asarray(r.target_enu_m)))

    def _run_law(self, k: int, sample: TeamSample, now_s: float) -> TeamCommand | None:
        if self._k0 is None:
            self._start_formation(k, sample)
            self.law.heading_rad = command_heading_rad(self.team.fly.heading, sample.rotation)
            self._log_unmeasured_delays()
            if not self._initial_mass_from_hover(sample, now_s):
                return self.last_command
        t = (k - self._k0) * self.period_s
        dt = (k - (self._last_law_k if self._last_law_k is not None else k - 1)) * self.period_s
        self._last_law_k = k
        fresh = fresh_mask(sample, self.team.fly.stale_after_s)
        # the staleness rule, per edge and in place: the law's weights a_ij of this tick
        stale_neighbours = drop_stale_neighbours(self.law.graph, fresh,
                                                 self.law.active_graph.weight)
        ref = reference_velocity(t, *self.ref_arrays)
        meas = self._law_input(sample, now_s)
        try:
            # The estimators adapt only while the formation is flown: afterwards the vehicles
            # switch to their own modes (land/hold) and the thrust applied is no longer ours.
            command = self.law.step(meas, ref, dt, adapt=self.machine.phase is Phase.FORMATION)
        except SingularCommandError as exc:
            self.machine.request_abort(f"t = {t:.2f} s: {exc}", operator=False)
            return self.last_command
        if not (np.isfinite(command.thrust_n).all() and np.isfinite(command.rate_cmd_radps).all()
                and np.isfinite(command.torque_nm).all()):
            self.machine.request_abort(f"t = {t:.2f} s: the law produced a non-finite command",
                                       operator=False)
            return self.last_command
        self.last_command = command
        self.formation_t_s = t
        log, self._next_log_k = log_due(k, self._k0, self.setup.log_every, self._next_log_k)
        if self.machine.phase is Phase.FORMATION:
            self.ages.record(sample.delay_s, sample.age_s, fresh, stale_neighbours)
            if log:
                self._log(t, sample, ref[0], command)
        return command

    def _law_input(self, sample: TeamSample, now_s: float) -> TeamMeasurement:
        """The samples as they are, or (fly.predict) predicted to when this tick's setpoints act:
        now plus the team's uplink delay (gcs/fly/predict.py); in formation, the audit compares
        each prediction with what the vehicles report for that instant."""
        held = sample.measurement()
        if self.audit is None:
            return held
        # each link's least one-way delay: the table's copy of the clock filters' (a column)
        least = (self.hot.clock_line[:, 3] if self._clocks_in_table
                 else np.array([p.clock.least_delay_s for p in self.proxies]))
        act = now_s + uplink_delay_s(least)
        h_pos = horizons_s(act, sample.position_taken_s)
        predicted = predict(held, h_pos, horizons_s(act, sample.attitude_taken_s))
        if self.machine.phase is Phase.FORMATION:
            self.audit.observe(sample.position_m, sample.velocity_mps, sample.position_taken_s,
                               sample.rotation, sample.omega_radps, sample.attitude_taken_s)
            self.audit.record(act, predicted, held, h_pos)
        return predicted

    def _log(self, t: float, sample: TeamSample, ref_velocity_enu_mps: np.ndarray,
             c: TeamCommand | None) -> None:
        """One record sample; `c` None (position mode: no law) records its figures as NaN."""
        p = sample.position_m
        self.formation_error_m = formation_error_m(p, self._offsets_m)  # no (n, n, 3) array
        law = {} if c is None else {
            "attitude_error": c.attitude_error, "omega_error_radps": c.omega_error_radps,
            "mass_estimate_kg": c.mass_estimate_kg,
            "inertia_estimate_kgm2": c.inertia_estimate_kgm2, "thrust_n": c.thrust_n,
            "force_enu_n": c.force_n}
        self.builder.append(t_s=t, position_enu_m=p, velocity_enu_mps=sample.velocity_mps,
                            reference_velocity_enu_mps=ref_velocity_enu_mps,
                            mass_true_kg=true_mass_kg(self.team, t), **law)

    def _send(self, c: TeamCommand, streaming: frozenset[int]) -> None:
        """Thrust / max thrust; actuators: thrust-preserving torque limit of (51), then torque /
        torque scale; rates: body-rate norm limit (docs/gcs.md)."""
        thrust = normalised_thrust(c.thrust_n, self.max_thrust_n)
        if self.setup.mode == "actuators":
            torque, limited = desaturate_torque(c.thrust_n, c.torque_nm, self.arm_m,
                                                self.anti_torque_m, self.rotor_max_n)
            vec = normalised_torque(torque, self.torque_max)
        elif self.setup.mode == "attitude":  # R^c itself; the autopilot limits its own tilt
            vec = self.ties.rotations_to_local(c.command_rotation)
            limited = np.zeros(self.n, dtype=bool)
        else:
            vec, limited = limit_rate_command(c.rate_cmd_radps, self.max_rate_radps,
                                              self.max_yaw_rate_radps)
        if self.machine.phase is Phase.FORMATION:
            self.limited_ticks += limited
        self._send_vectors(vec, thrust, streaming)

    def _send_vectors(self, vec: np.ndarray, thrust: np.ndarray,
                      streaming: frozenset[int]) -> None:
        """Row i of ``vec`` (rates, attitude or torque, as the mode sends) and ``thrust`` to
        vehicle i if it is streaming; rates mode packs the team in one call."""
        if streaming != self._streaming_rows[0]:  # a new set: its rows, once
            picked = [i for i in range(self.n) if self.ids[i] in streaming]
            self._streaming_rows = (streaming, picked, np.asarray(picked, dtype=np.intp))
        _, rows, at = self._streaming_rows
        if self.setup.mode == "rates":  # the team at once (gcs.link.fastpath), bad rows one by one
            if self._team_setpoints is None:
                self._team_setpoints = TeamSetpoints(self.proxies)
                self._batchable = np.array([p.batch_sendable for p in self.proxies], dtype=bool)
            ok = (np.isfinite(vec).all(axis=1) & np.isfinite(thrust) & self._batchable)[at]
            self._team_setpoints.send_rates_thrust(at[ok].tolist(), vec, thrust)
            rows = at[~ok].tolist()
        for i in rows:
            self._send_one(i, self.proxies[i], vec[i], thrust[i])

    def _send_one(self, i: int, p: VehicleProxy, vec: np.ndarray, thrust_norm: float) -> None:
        try:
            if self.setup.mode == "actuators":
                p.send_actuator_controls(vec, thrust_norm)
            elif self.setup.mode == "attitude":
                p.send_attitude_thrust(vec, thrust_norm)
            else:
                p.send_rates_thrust(vec, thrust_norm)
        except SetpointError as exc:
            self._setpoint_errors += 1
            self.machine.request_abort(str(exc), operator=False)

    # --- records ---------------------------------------------------------------------------------

    def _statustexts(self) -> dict[str, list[dict[str, Any]]]:
        """Every vehicle's STATUSTEXT (severity, text, time after the flight start in s)."""
        t0 = self._t0_s
        return {str(self.ids[i]): [{"t_s": round(e.rx_time_s - t0, 3), "severity": e.severity_name,
                                    "text": e.text} for e in p.statustexts.texts()]
                for i, p in enumerate(self.proxies)}

    def _vehicle_kind(self, vehicle_id: int) -> str:
        """'PX4', or with a note 'PX4 (vehicle-emu px4)': the autopilot family its HEARTBEAT
        named (the machine's profile) and what the command line knows of the vehicle."""
        name = self.machine.profile(vehicle_id).name
        note = self.vehicle_notes.get(vehicle_id)
        return f"{name} ({note})" if note else name

    def _write_records(self, outcome: Outcome) -> FlyResult:
        out = self.options.out_dir
        if len(self.builder) == 0:
            logger.warning("no formation samples: no report written")
            return FlyResult(outcome, None, out, None)
        stats = [p.stats() for p in self.proxies]
        link = link_report(
            self.ids, self.ages,
            setpoints_sent=[s.proxy.setpoints_sent for s in stats],
            telemetry_received=[s.proxy.messages_accepted for s in stats],
            telemetry_lost=[s.sequence.lost for s in stats],
            extra=[{"limited_ticks": int(self.limited_ticks[i]),
                    "thrust_clamped": s.proxy.thrust_clamped,
                    "torque_clamped": s.proxy.torque_clamped,
                    "link_lost_events": s.proxy.link_lost_events,
                    "heartbeat_stale_events": s.proxy.heartbeat_stale_events,
                    "stranger_address": s.proxy.stranger_address,
                    "unknown_sysid_frames": s.port.unknown_sysid_frames,
                    "gcs_socket_dropped": s.udp.rx_dropped_kernel,
                    "command_retries": getattr(s.commands, "retries", None),
                    "lost": self.ids[i] in self.machine.lost,
                    "round_trip": round_trip_report(self.proxies[i].round_trips_s()),
                    "clock": clock_report(self.proxies[i].clock.estimate()),
                    "prediction": prediction_report(
                        self.audit.figures(i) if self.audit is not None else None)}
                   for i, s in enumerate(stats)],
        )
        tick = self.ticks.report()
        log = self.builder.build(extra={
            "link": link,
            "tick": {**tick, "scheduling": (self.scheduling.detail if self.scheduling is not None
                                            else "not set")},
            "outcome": {"exit_code": outcome.exit_code, "reason": outcome.reason},
            # records the disk could not take in time (dropped, counted; gcs/link/tlog.py)
            "tlog": ({"records": self._tlog.records, "dropped_records": self._tlog.dropped_records,
                      "write_errors": self._tlog.write_errors} if self._tlog is not None else None),
            "hover_estimates": {str(vid): dataclasses.asdict(e)
                                for vid, e in self.hover_estimates.items()},
            "go_to_start": {str(vid): {**dataclasses.asdict(r),
                                       "error_at_t0_m": self._start_error_m.get(vid)}
                            for vid, r in self.machine.goto_results.items()},
            "events": self.machine.notes[-50:],
            "vehicle_kinds": [self._vehicle_kind(vid) for vid in self.ids],
            "statustext": self._statustexts(),
            # numba compiles during the flight (each stalled the tick while it ran)
            "compiled_after_ready": self.compiled_after_ready,
        })
        report = build_report(log)
        write_report(out / REPORT_NAME, report)
        save_timeseries(log, out / TIMESERIES_NAME)
        if self.options.figures:
            from gcs.plots import write_figures

            write_figures(log, out, pairs=[(e.i, e.j) for e in self.team.graph.edges])
        return FlyResult(outcome, log, out, report)


async def fly(team: TeamConfig, options: FlyOptions,
              status_factory: Callable[[Flight], Any] | None = None) -> FlyResult:
    """Fly `team` once; returns when every vehicle is landed/holding (or lost) and the records
    are written. Raises FlightSetupError before opening any link if the setup is invalid."""
    setup = prepare(team, options)
    return await Flight(setup, options, status_factory).run()


__all__ = [
    "FlightSetupError", "FlyOptions", "FlyResult", "Flight", "fly", "prepare", "true_mass_kg",
]
