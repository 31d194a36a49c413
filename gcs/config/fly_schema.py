"""The team file's `fly:` section as frozen dataclasses: how `gcs fly` flies the team (its
modes' tick rates and gains, sequence, safety rules, link timing). Read by fly_section."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gcs.config.declare import key
from gcs.config.modes import (
    AUTO_MODE,
    FLY_HEADINGS,
    FLY_INITIAL_MASSES,
    FLY_MODES,
    FLY_SCHEDULING,
    FLY_STARTS,
    ControlMode,
    FlyAction,
    fly_mode,
)

if TYPE_CHECKING:
    from gcs.config.yamlnode import Node

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class FlyModeConfig:
    """`gcs fly` settings of one control mode: the tick rate over the link and, where the paper's
    attitude gains are not stable at that rate (docs/control-law.md, "Discrete-time
    implementation"), the gains flown instead."""

    tick_rate_hz: float = key(gt=0.0, le=1000.0)
    # None: controller.gains.alpha_eps / alpha_omega (actuators mode)
    alpha_eps: float | None = key(None, gt=0.0)
    alpha_omega: float | None = key(None, gt=0.0)
    # rates mode: norm limit of the roll/pitch body-rate command
    max_rate_radps: float = key(1.0, gt=0.0)
    # rates mode: limit of the yaw-rate command, on its own
    max_yaw_rate_radps: float = key(0.5, gt=0.0)
    # the gains flown in this mode where the autopilot's own loops need softer ones than the
    # paper's (gcs/control/cascade.py); None: controller.gains
    k_eps: float | None = key(None, gt=0.0)  # rates mode
    k_eps_yaw: float | None = key(None, gt=0.0)  # rates mode
    alpha_p: float | None = key(None, gt=0.0)
    c_p: float | None = key(None, gt=0.0)
    alpha_rho: float | None = key(None, gt=0.0)  # None: controller.gains.alpha_rho (actuators)


@dataclass(frozen=True, slots=True)
class PositionModeConfig:
    """`fly.position`: the baseline's settings. It runs no law, so it has no gains: only the
    rate at which the slot setpoints are sent (the autopilot closes every loop on board)."""

    tick_rate_hz: float = key(50.0, gt=0.0, le=1000.0)


def _ordered(node: Node, fence: GeofenceConfig) -> None:
    for k, axis in enumerate("xyz"):
        if not fence.min_enu_m[k] < fence.max_enu_m[k]:
            node.child("max_enu_m").fail(
                f"expected max > min on every axis, got {axis}: min "
                f"{fence.min_enu_m[k]!r} >= max {fence.max_enu_m[k]!r}"
            )


@dataclass(frozen=True, slots=True)
class GeofenceConfig:
    """Axis-aligned box in the world ENU frame [m]; checked during the formation phase."""

    min_enu_m: Vec3 = key()
    max_enu_m: Vec3 = key()


@dataclass(frozen=True, slots=True)
class FormationCheckConfig:
    """`fly.formation_check`: from formation time `after_s` on, the formation error must stay
    at or below max(`max_error_m`, `max_fraction` x its value at t = 0), else the flight stops
    with exit 1 (the vehicles do not follow the law; docs/gcs.md)."""

    after_s: float = key(10.0, ge=0.0)
    max_error_m: float = key(1.0, gt=0.0)
    max_fraction: float = key(0.5, gt=0.0)


GO_TO_START_ENABLED = ("auto", "true", "false")


def _enabled(node: Node, default: str) -> str:
    """fly.go_to_start.enabled: auto, or a flag (true / false, as YAML or as a string)."""
    if isinstance(node.value, bool):
        return "true" if node.value else "false"
    return node.string(default, choices=GO_TO_START_ENABLED)


@dataclass(frozen=True, slots=True)
class GoToStartConfig:
    """`fly.go_to_start`: before the formation, fly each vehicle to its team-file start position
    (`initial.position_enu_m`) with position setpoints, first vertically to the start altitude,
    then across at it, and start the law once every one has settled (docs/gcs.md, "Go to
    start"). `enabled`: auto (the vehicles that took off in this flight), true (every vehicle),
    false (none: the law starts where the vehicles are)."""

    enabled: str = key("auto", read=_enabled)
    tolerance_m: float = key(0.3, gt=0.0)  # settled: within this of the start position ...
    max_speed_mps: float = key(0.1, gt=0.0)  # ... and drifting slower than this ...
    settle_s: float = key(2.0, ge=0.0)  # ... continuously for this long
    timeout_s: float = key(60.0, gt=0.0)  # every vehicle settled within this, else exit 1
    # the position setpoint moves along each leg at this speed
    cruise_speed_mps: float = key(2.0, gt=0.0, le=20.0)
    # start positions lower than this are refused (config error)
    min_altitude_m: float = key(2.0, gt=0.0)


@dataclass(frozen=True, slots=True)
class ResponseConfig:
    """`fly.response`: how the vehicles' own loops answer a setpoint, for the cascade criterion
    (gcs/control/cascade.py AutopilotResponse; absent: each autopilot's recorded default)."""

    rate_damping: float = key(gt=0.0)
    rate_natural_radps: float = key(gt=0.0)
    rate_dead_time_s: float = key(ge=0.0)
    yaw_time_constant_s: float = key(gt=0.0)
    yaw_dead_time_s: float = key(ge=0.0)
    attitude_p_per_s: float = key(gt=0.0)
    thrust_time_constant_s: float = key(gt=0.0)


RESPONSE_KEYS = tuple(ResponseConfig.__dataclass_fields__)


def _control_mode(node: Node, default: Any) -> ControlMode | str:
    return fly_mode(node.string(default, FLY_MODES))


def _heading(node: Node, default: str | float) -> str | float:
    """fly.heading: 'hold', 'paper', or a compass heading in degrees."""
    if node.absent:
        return default
    if isinstance(node.value, str):
        if node.value not in FLY_HEADINGS:
            node.fail(f"expected 'hold', 'paper' or a compass heading in degrees, got "
                      f"{node.value!r}")
        return node.value
    return node.number(ge=-360.0, le=360.0)


@dataclass(frozen=True, slots=True)
class FlyConfig:
    """The `fly:` section: flight sequence, safety rules and link timing of `gcs fly`."""

    # fly.mode: the control mode gcs fly flies (controller.mode is gcs sim's); AUTO_MODE: rates, or
    # attitude where rates' loops fail the cascade criterion at link_delay_s (gcs/fly/setup.py)
    control_mode: ControlMode | str = key(AUTO_MODE, name="mode", read=_control_mode)
    rates: FlyModeConfig = key(FlyModeConfig(100.0))
    actuators: FlyModeConfig = key(FlyModeConfig(250.0))
    attitude: FlyModeConfig = key(FlyModeConfig(100.0))
    position: PositionModeConfig = key(PositionModeConfig())
    # the heading R^c is turned to about its thrust axis (position mode: the slots' yaw): "hold"
    # (each vehicle's at the formation start), "paper" (eq. (14) as it is: east), or a compass
    # heading [deg, 0 north, 90 east]
    heading: str | float = key("hold", read=_heading)
    # auto: take off the vehicles that report being on the ground
    start: str = key("auto", choices=FLY_STARTS)
    takeoff_altitude_m: float = key(2.5, ge=0.5, le=1000.0)  # above home
    end_action: FlyAction = key(FlyAction.LAND)  # after the formation phase
    abort_action: FlyAction = key(FlyAction.LAND)  # Ctrl-C, abort key, geofence, failed check
    link_loss_action: FlyAction = key(FlyAction.HOLD)  # the other vehicles when one link is lost
    # telemetry older than this is stale (see docs/gcs.md)
    stale_after_s: float = key(0.1, gt=0.0)
    # in flight: position/attitude older than this -> lost
    link_lost_after_s: float = key(0.5, gt=0.0)
    # in flight: position/attitude arriving more than this long after the vehicle took them (its
    # own stamps) stops the formation with abort_action (docs/gcs.md, "Link delay")
    max_data_age_s: float = key(0.3, gt=0.0, le=10.0)
    # TIMESYNC round-trip requests; 0: none
    timesync_period_s: float = key(0.5, ge=0.0, le=60.0)
    # the law reads the states predicted to when its setpoints act (gcs/control/predict.py)
    predict: bool = key(True)
    # the law's velocity takes the reported position's rate below 1 / this [s]; 0: the reported
    # velocity as it is (gcs/fly/consistent.py)
    velocity_from_position_s: float = key(0.2, ge=0.0, le=60.0)
    # the law's acceleration takes that velocity's rate below 1 / this [s], the accelerometer's
    # (turned by the reported attitude) above; 0: the accelerometer's alone
    # (gcs/fly/consistent.py)
    acceleration_from_velocity_s: float = key(0.5, ge=0.0, le=60.0)
    # the operating system's priority for the ground station (gcs/fly/sched.py)
    scheduling: str = key("auto", choices=FLY_SCHEDULING)
    # any valid message from the vehicle keeps its link ALIVE; none for this long -> LOST (a
    # vehicle that sends only its 1 Hz HEARTBEAT, as ArduPilot does until asked, stays ALIVE)
    link_timeout_s: float = key(3.0, gt=0.0)
    max_tilt_rad: float = key(1.0, gt=0.0, le=math.pi)  # abort above this tilt (formation phase)
    geofence: GeofenceConfig | None = key(None, check=_ordered)
    # time-series samples; must divide every mode's tick rate
    log_rate_hz: float = key(50.0, gt=0.0)
    # emulators compiling, autopilots booting (PX4 SITL 10-25 s)
    connect_timeout_s: float = key(60.0, gt=0.0)
    takeoff_timeout_s: float = key(60.0, gt=0.0)
    # takeoff done within this of takeoff_altitude_m
    takeoff_tolerance_m: float = key(0.3, gt=0.0)
    land_timeout_s: float = key(120.0, gt=0.0)
    # arming waits this long for the vehicles to be ready
    arm_timeout_s: float = key(60.0, gt=0.0)
    arm_retry_s: float = key(1.0, ge=0.1)  # between two arming attempts of one vehicle
    # a commanded mode (or arming) must show in HEARTBEAT within this
    mode_timeout_s: float = key(3.0, gt=0.0)
    formation_check: FormationCheckConfig = key(FormationCheckConfig())
    response: ResponseConfig | None = key(None)  # None: the autopilot's recorded default
    # "from_hover": every vehicle's mhat_i(0) from its hover thrust, as `estimates.mhat:
    # from_hover` (gcs fly only; gcs sim keeps the scenario's estimates)
    initial_mass: str = key("team", choices=FLY_INITIAL_MASSES)
    # one-way link delay the cascade criterion assumes [s]
    link_delay_s: float = key(0.01, ge=0.0, le=1.0)
    go_to_start: GoToStartConfig = key(GoToStartConfig())

    def mode(self, name: ControlMode) -> FlyModeConfig:
        """The settings of law mode `name` (rates, actuators or attitude)."""
        return {ControlMode.RATES: self.rates, ControlMode.ACTUATORS: self.actuators,
                ControlMode.ATTITUDE: self.attitude}[name]

    def tick_rate_hz(self, name: ControlMode) -> float:
        """The tick rate of control mode `name` (FLY_CONTROL_MODES: a law mode or position)."""
        if name == ControlMode.POSITION:
            return self.position.tick_rate_hz
        return self.mode(name).tick_rate_hz
