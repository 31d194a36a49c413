"""The team file's `fly:` section as frozen dataclasses: how `gcs fly` flies the team (its
modes' tick rates and gains, sequence, safety rules, link timing). Read by fly_section."""

from __future__ import annotations

from dataclasses import dataclass

from gcs.config.modes import AUTO_MODE, ControlMode, FlyAction

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class FlyModeConfig:
    """`gcs fly` settings of one control mode: the tick rate over the link and, where the paper's
    attitude gains are not stable at that rate (docs/control-law.md, "Discrete-time
    implementation"), the gains flown instead."""

    tick_rate_hz: float
    alpha_eps: float | None = None  # None: controller.gains.alpha_eps (actuators mode)
    alpha_omega: float | None = None  # None: controller.gains.alpha_omega (actuators mode)
    max_rate_radps: float = 1.0  # rates mode: norm limit of the roll/pitch body-rate command
    max_yaw_rate_radps: float = 0.5  # rates mode: limit of the yaw-rate command, on its own
    # the gains flown in this mode where the autopilot's own loops need softer ones than the
    # paper's (gcs/mission/cascade.py); None: controller.gains
    k_eps: float | None = None  # rates mode
    k_eps_yaw: float | None = None  # rates mode
    alpha_p: float | None = None
    c_p: float | None = None
    alpha_rho: float | None = None  # None: controller.gains.alpha_rho (actuators mode)


@dataclass(frozen=True, slots=True)
class PositionModeConfig:
    """`fly.position`: the baseline's settings. It runs no law, so it has no gains: only the
    rate at which the slot setpoints are sent (the autopilot closes every loop on board)."""

    tick_rate_hz: float = 50.0


@dataclass(frozen=True, slots=True)
class GeofenceConfig:
    """Axis-aligned box in the world ENU frame [m]; checked during the formation phase."""

    min_enu_m: Vec3
    max_enu_m: Vec3


@dataclass(frozen=True, slots=True)
class FormationCheckConfig:
    """`fly.formation_check`: from formation time `after_s` on, the formation error must stay
    at or below max(`max_error_m`, `max_fraction` x its value at t = 0), else the flight stops
    with exit 1 (the vehicles do not follow the law; docs/gcs.md)."""

    after_s: float = 10.0
    max_error_m: float = 1.0
    max_fraction: float = 0.5


GO_TO_START_ENABLED = ("auto", "true", "false")


@dataclass(frozen=True, slots=True)
class GoToStartConfig:
    """`fly.go_to_start`: before the formation, fly each vehicle to its team-file start position
    (`initial.position_enu_m`) with position setpoints, first vertically to the start altitude,
    then across at it, and start the law once every one has settled (docs/gcs.md, "Go to
    start"). `enabled`: auto (the vehicles that took off in this flight), true (every vehicle),
    false (none: the law starts where the vehicles are)."""

    enabled: str = "auto"
    tolerance_m: float = 0.3  # settled: within this of the start position ...
    max_speed_mps: float = 0.1  # ... and drifting slower than this ...
    settle_s: float = 2.0  # ... continuously for this long
    timeout_s: float = 60.0  # every vehicle settled within this, else the flight stops
    cruise_speed_mps: float = 2.0  # the position setpoint moves along each leg at this speed
    min_altitude_m: float = 2.0  # start positions lower than this are refused (config error)


@dataclass(frozen=True, slots=True)
class ResponseConfig:
    """`fly.response`: how the vehicles' own loops answer a setpoint, for the cascade criterion
    (gcs/mission/cascade.py AutopilotResponse; absent: each autopilot's recorded default)."""

    rate_damping: float
    rate_natural_radps: float
    rate_dead_time_s: float
    yaw_time_constant_s: float
    yaw_dead_time_s: float
    attitude_p_per_s: float
    thrust_time_constant_s: float


RESPONSE_KEYS = tuple(ResponseConfig.__dataclass_fields__)


@dataclass(frozen=True, slots=True)
class FlyConfig:
    """The `fly:` section: flight sequence, safety rules and link timing of `gcs fly`."""

    # fly.mode: the control mode gcs fly flies (controller.mode is gcs sim's); AUTO_MODE: rates, or
    # attitude where rates' loops fail the cascade criterion at link_delay_s (gcs/fly/setup.py)
    control_mode: ControlMode | str = AUTO_MODE
    rates: FlyModeConfig = FlyModeConfig(100.0)
    actuators: FlyModeConfig = FlyModeConfig(250.0)
    attitude: FlyModeConfig = FlyModeConfig(100.0)
    position: PositionModeConfig = PositionModeConfig()
    # the heading R^c is turned to about its thrust axis (position mode: the slots' yaw): "hold"
    # (each vehicle's at the formation start), "paper" (eq. (14) as it is: east), or a compass
    # heading [deg, 0 north, 90 east]
    heading: str | float = "hold"
    start: str = "auto"  # auto: take off the vehicles that report being on the ground
    takeoff_altitude_m: float = 2.5  # above home
    end_action: FlyAction = FlyAction.LAND  # after the formation phase
    abort_action: FlyAction = FlyAction.LAND  # Ctrl-C, abort key, geofence, failed check
    link_loss_action: FlyAction = FlyAction.HOLD  # the other vehicles when one link is lost
    stale_after_s: float = 0.1  # telemetry older than this is stale (see docs/gcs.md)
    link_lost_after_s: float = 0.5  # in flight: position/attitude older than this -> lost
    # in flight: position/attitude arriving more than this long after the vehicle took them (its
    # own stamps) stops the formation with abort_action (docs/gcs.md, "Link delay")
    max_data_age_s: float = 0.3
    timesync_period_s: float = 0.5  # TIMESYNC round-trip requests; 0: none
    # the law reads the states predicted to when its setpoints act (gcs/fly/predict.py)
    predict: bool = True
    # the law's velocity takes the reported position's rate below 1 / this [s]; 0: the reported
    # velocity as it is (gcs/fly/consistent.py)
    velocity_from_position_s: float = 0.2
    # the operating system's priority for the ground station (gcs/fly/sched.py)
    scheduling: str = "auto"
    # any valid message from the vehicle keeps its link ALIVE; none for this long -> LOST (a
    # vehicle that sends only its 1 Hz HEARTBEAT, as ArduPilot does until asked, stays ALIVE)
    link_timeout_s: float = 3.0
    max_tilt_rad: float = 1.0  # abort above this tilt (formation phase)
    geofence: GeofenceConfig | None = None
    log_rate_hz: float = 50.0  # time-series samples; must divide every mode's tick rate
    connect_timeout_s: float = 60.0  # emulators compiling, autopilots booting (PX4 SITL 10-25 s)
    takeoff_timeout_s: float = 60.0
    takeoff_tolerance_m: float = 0.3  # takeoff done within this of takeoff_altitude_m
    land_timeout_s: float = 120.0
    arm_timeout_s: float = 60.0  # arming waits this long for the vehicles to be ready
    arm_retry_s: float = 1.0  # between two arming attempts of one vehicle
    mode_timeout_s: float = 3.0  # a commanded mode (or arming) must show in HEARTBEAT within
    formation_check: FormationCheckConfig = FormationCheckConfig()
    response: ResponseConfig | None = None  # None: the autopilot's recorded default
    # "from_hover": every vehicle's mhat_i(0) from its hover thrust, as `estimates.mhat:
    # from_hover` (gcs fly only; gcs sim keeps the scenario's estimates)
    initial_mass: str = "team"
    link_delay_s: float = 0.01  # one-way link delay the cascade criterion assumes [s]
    go_to_start: GoToStartConfig = GoToStartConfig()

    def mode(self, name: ControlMode) -> FlyModeConfig:
        """The settings of law mode `name` (rates, actuators or attitude)."""
        return {ControlMode.RATES: self.rates, ControlMode.ACTUATORS: self.actuators,
                ControlMode.ATTITUDE: self.attitude}[name]

    def tick_rate_hz(self, name: ControlMode) -> float:
        """The tick rate of control mode `name` (FLY_CONTROL_MODES: a law mode or position)."""
        if name == ControlMode.POSITION:
            return self.position.tick_rate_hz
        return self.mode(name).tick_rate_hz
