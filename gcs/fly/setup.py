"""Set-up policy of `gcs fly`, pure: the mode, law, rate and gains a team file flies, checked.

`prepare` turns a team file and the command line's overrides into a `FlightSetup` (the mode and
why, the gains, the mission plan, the streams to ask for, the stability criterion evaluated) or
raises `FlightSetupError` before any link is opened. No sockets, no asyncio.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.config import ConfigError, TeamConfig, check_go_to_start
from gcs.config.modes import (
    AUTO_MODE,
    AUTO_MODES,
    FLY_ACTIONS,
    FLY_CONTROL_MODES,
    FLY_MODES,
    ControlMode,
    FlyAction,
    as_strings,
    fly_mode,
)
from gcs.config.schema import whole_ratio
from gcs.control.cascade import (
    AutopilotResponse,
    CascadeGains,
    cascade_margins,
    laplacian_eigenvalues,
    passes,
    verdict,
)
from gcs.control.gains import LawGains
from gcs.control.stability import (
    MIN_DECAY_PER_S,
    delays_ticks,
    describe_margins,
    torque_margins,
)
from gcs.flightlog import AUTOPILOT_CONTROLLER, FlightLog
from gcs.fly.delay import DelayJudge, TorqueDelayJudge
from gcs.fly.measure import HOVER_RATE_HZ, HOVER_WINDOW_S
from gcs.mission.autopilots import PROFILES
from gcs.mission.goto import GoToStartPlan
from gcs.mission.plan import MissionPlan, Outcome
from gcs.mission.safety import SafetyRules

MAX_POSITION_RATE_HZ = 100.0
#: EXTENDED_SYS_STATE (landed state: preflight, takeoff, stopping); ArduPilot sends it only when
#: asked with SET_MESSAGE_INTERVAL (it is in none of its stream groups).
LANDED_STATE_RATE_HZ = 5.0


class FlightSetupError(Exception):
    """The flight cannot start as configured (before any link is opened); one line."""


@dataclass(frozen=True, slots=True)
class FlyOptions:
    """Command-line overrides of the team file for one flight (None: the file's value)."""

    out_dir: Path
    mode: str | None = None  # one of FLY_MODES
    law: str | None = None
    tick_rate_hz: float | None = None
    duration_s: float | None = None
    end_action: str | None = None  # one of FLY_ACTIONS
    figures: bool = True
    status: str = "auto"  # auto | rich | plain | off
    abort_key: bool = True
    connect_timeout_s: float | None = None


@dataclass(frozen=True, slots=True)
class FlightSetup:
    """Everything derived from the team file before flying (pure; see `prepare`)."""

    team: TeamConfig
    mode: ControlMode
    law: str
    tick_rate_hz: float
    gains: LawGains
    plan: MissionPlan
    requested_rates_hz: dict[str, float]
    log_every: int
    stability: str  # the discrete-time criterion, evaluated (for the log and the report)
    # the criterion again at each link's measured delay, in preflight (the cascade's in rates
    # and attitude mode, the torque loop's in actuators mode)
    delay_judge: DelayJudge | TorqueDelayJudge | None = None
    mode_choice: str = ""  # which mode is flown and why (resolve_mode)


@dataclass(frozen=True, slots=True)
class FlyResult:
    outcome: Outcome
    log: FlightLog | None
    out_dir: Path
    report: dict[str, Any] | None


def cascade_check(team: TeamConfig, mode: ControlMode, gains: LawGains,
                  rate_hz: float) -> tuple[str, dict[int, str], DelayJudge]:
    """The cascade criterion of `mode` for every autopilot gcs fly flies (gcs/control/cascade.py).

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


def _mode_gains(team: TeamConfig, mode: ControlMode) -> LawGains:
    """The law's gains as flown in `mode`: fly.<mode>'s over controller.gains."""
    mode_cfg, g = team.fly.mode(mode), team.controller.gains
    flown = {name: getattr(mode_cfg, name) for name in ("k_eps", "k_eps_yaw", "alpha_p", "c_p")
             if getattr(mode_cfg, name) is not None}
    torque = mode == ControlMode.ACTUATORS
    return g._replace(
        alpha_eps=mode_cfg.alpha_eps if torque and mode_cfg.alpha_eps else g.alpha_eps,
        alpha_omega=mode_cfg.alpha_omega if torque and mode_cfg.alpha_omega else g.alpha_omega,
        alpha_rho=mode_cfg.alpha_rho if torque and mode_cfg.alpha_rho else g.alpha_rho,
        **flown,
    )


def resolve_mode(team: TeamConfig, requested: str | None,
                 tick_rate_hz: float | None = None) -> tuple[ControlMode, str]:
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
    mode = fly_mode(requested) if requested else fly.control_mode
    if mode != AUTO_MODE:
        source = "--mode" if requested else "fly.mode"
        return mode, f"mode {mode} ({source})"
    eigenvalues = laplacian_eigenvalues(team.laplacian())
    declared = _declared_response(team)
    responses = ([("every vehicle", declared)] if declared is not None else
                 [(p.name, p.response) for p in PROFILES.values()])
    failed: dict[ControlMode, list[str]] = {}
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
        raise FlightSetupError(f"mode {options.mode!r}: expected one of {as_strings(FLY_MODES)}")
    mode, mode_choice = resolve_mode(team, options.mode, options.tick_rate_hz)
    if mode not in FLY_CONTROL_MODES:
        raise FlightSetupError(
            f"mode {str(mode)!r}: expected one of {as_strings(FLY_CONTROL_MODES)}")
    position = mode == ControlMode.POSITION
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
    log_every = whole_ratio(rate, fly.log_rate_hz)
    if log_every is None:
        raise FlightSetupError(
            f"tick rate {rate:g} Hz must be a multiple of fly.log_rate_hz {fly.log_rate_hz:g}")
    # position mode: the team file's gains only to build the (unused) law object
    gains = team.controller.gains if position else _mode_gains(team, mode)
    loop_refusals: dict[int, str] = {}
    judge: DelayJudge | TorqueDelayJudge | None = None
    if position:
        stability = ("position mode: no law runs on the ground station; each autopilot closes "
                     "every loop on board (no cascade or torque criterion applies)")
    elif mode == ControlMode.ACTUATORS:
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
        judge = TorqueDelayJudge(team.ids(), inertias, gains.alpha_eps, gains.alpha_omega, rate)
    else:  # rates, attitude: the law's loops over each autopilot's own (cascade.py)
        stability, loop_refusals, judge = cascade_check(team, mode, gains, rate)
    try:
        check_go_to_start(team)
    except ConfigError as exc:
        raise FlightSetupError(f"config error: {exc}") from None
    end_action = options.end_action or fly.end_action
    if end_action not in FLY_ACTIONS:
        raise FlightSetupError(
            f"end action {end_action!r}: expected one of {as_strings(FLY_ACTIONS)}")
    end_action = FlyAction(end_action)
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
                       log_every, stability, judge, mode_choice)


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
