"""The team file's optional `fly:` section (how `gcs fly` flies the team) -> FlyConfig, and the
check of the start positions that `gcs fly` makes before a go-to-start phase."""

from __future__ import annotations

import math

from gcs.config.fly_schema import (
    GO_TO_START_ENABLED,
    RESPONSE_KEYS,
    FlyConfig,
    FlyModeConfig,
    FormationCheckConfig,
    GeofenceConfig,
    GoToStartConfig,
    PositionModeConfig,
    ResponseConfig,
)
from gcs.config.modes import (
    FLY_ACTIONS,
    FLY_CONTROL_MODES,
    FLY_HEADINGS,
    FLY_INITIAL_MASSES,
    FLY_MODES,
    FLY_SCHEDULING,
    FLY_STARTS,
    FlyAction,
    fly_mode,
)
from gcs.config.schema import ConfigError, TeamConfig, whole_ratio
from gcs.config.yamlnode import Node


def _fly_mode(node: Node, default: FlyModeConfig) -> FlyModeConfig:
    if node.absent:
        return default
    node.keys("", "tick_rate_hz alpha_eps alpha_omega max_rate_radps max_yaw_rate_radps k_eps "
                  "k_eps_yaw alpha_p c_p alpha_rho")
    return FlyModeConfig(
        node.child("tick_rate_hz").number(default.tick_rate_hz, gt=0.0, le=1000.0),
        node.child("alpha_eps").number(None, gt=0.0),
        node.child("alpha_omega").number(None, gt=0.0),
        node.child("max_rate_radps").number(default.max_rate_radps, gt=0.0),
        node.child("max_yaw_rate_radps").number(default.max_yaw_rate_radps, gt=0.0),
        node.child("k_eps").number(None, gt=0.0),
        node.child("k_eps_yaw").number(None, gt=0.0),
        node.child("alpha_p").number(None, gt=0.0),
        node.child("c_p").number(None, gt=0.0),
        node.child("alpha_rho").number(None, gt=0.0),
    )


def _position_mode(node: Node, default: PositionModeConfig) -> PositionModeConfig:
    """fly.position: the baseline runs no law, so its block has no gains, only its tick rate."""
    if node.absent:
        return default
    node.keys("", "tick_rate_hz")
    return PositionModeConfig(
        node.child("tick_rate_hz").number(default.tick_rate_hz, gt=0.0, le=1000.0))


def _response(node: Node) -> ResponseConfig | None:
    if node.absent:
        return None
    node.keys(" ".join(RESPONSE_KEYS))
    values = {k: node.child(k).number(ge=0.0 if k.endswith("dead_time_s") else None,
                                      gt=None if k.endswith("dead_time_s") else 0.0)
              for k in RESPONSE_KEYS}
    return ResponseConfig(**values)


def _formation_check(node: Node, d: FormationCheckConfig) -> FormationCheckConfig:
    if node.absent:
        return d
    node.keys("", "after_s max_error_m max_fraction")
    return FormationCheckConfig(
        node.child("after_s").number(d.after_s, ge=0.0),
        node.child("max_error_m").number(d.max_error_m, gt=0.0),
        node.child("max_fraction").number(d.max_fraction, gt=0.0),
    )


def _go_to_start(node: Node, d: GoToStartConfig) -> GoToStartConfig:
    """fly.go_to_start (docs/configuration.md); `enabled` is auto, true or false."""
    if node.absent:
        return d
    node.keys("", "enabled tolerance_m max_speed_mps settle_s timeout_s cruise_speed_mps "
                  "min_altitude_m")
    enabled_node = node.child("enabled")
    if enabled_node.absent:
        enabled = d.enabled
    elif isinstance(enabled_node.value, bool):
        enabled = "true" if enabled_node.value else "false"
    else:
        enabled = enabled_node.string(choices=GO_TO_START_ENABLED)
    return GoToStartConfig(
        enabled,
        node.child("tolerance_m").number(d.tolerance_m, gt=0.0),
        node.child("max_speed_mps").number(d.max_speed_mps, gt=0.0),
        node.child("settle_s").number(d.settle_s, ge=0.0),
        node.child("timeout_s").number(d.timeout_s, gt=0.0),
        node.child("cruise_speed_mps").number(d.cruise_speed_mps, gt=0.0, le=20.0),
        node.child("min_altitude_m").number(d.min_altitude_m, gt=0.0),
    )


def check_go_to_start(team: TeamConfig) -> None:
    """`gcs fly` with go-to-start on: every start position (`initial.position_enu_m`) must be a
    safe place to fly to, at or above fly.go_to_start.min_altitude_m and inside fly.geofence;
    raises ConfigError naming the key path and the vehicle. (`gcs sim` starts its plants there
    whatever the altitude, so the reader itself does not ask for this.)"""
    g = team.fly.go_to_start
    if g.enabled == "false":
        return
    for k, v in enumerate(team.vehicles):
        p = v.initial.position_enu_m
        key, name = f"vehicles[{k}].initial.position_enu_m", f"vehicle {v.id} (sysid {v.sysid})"
        if p[2] < g.min_altitude_m:
            raise ConfigError(team.source_path, key, (
                f"{name}: start altitude z = {p[2]:g} m is below fly.go_to_start.min_altitude_m "
                f"{g.min_altitude_m:g}: the go-to-start phase flies every vehicle to its start "
                "position; set it higher, or fly.go_to_start.enabled: false to start the law "
                "where the vehicles are"))
        fence = team.fly.geofence
        for axis in range(3) if fence is not None else ():
            if not fence.min_enu_m[axis] < p[axis] < fence.max_enu_m[axis]:
                raise ConfigError(team.source_path, key, (
                    f"{name}: start position {'xyz'[axis]} = {p[axis]:g} m is outside "
                    f"fly.geofence [{fence.min_enu_m[axis]:g}, {fence.max_enu_m[axis]:g}] m"))


def _heading(node: Node) -> str | float:
    """fly.heading: 'hold', 'paper', or a compass heading in degrees."""
    if node.absent:
        return "hold"
    if isinstance(node.value, str):
        if node.value not in FLY_HEADINGS:
            node.fail(f"expected 'hold', 'paper' or a compass heading in degrees, got "
                      f"{node.value!r}")
        return node.value
    return node.number(ge=-360.0, le=360.0)


def read_fly(node: Node) -> FlyConfig:
    """The optional `fly:` section (every key optional; see docs/configuration.md)."""
    d = FlyConfig()
    if node.absent:
        return d
    node.keys(
        "",
        "mode rates actuators attitude position heading start takeoff_altitude_m end_action "
        "abort_action link_loss_action stale_after_s link_lost_after_s link_timeout_s "
        "max_tilt_rad geofence log_rate_hz connect_timeout_s takeoff_timeout_s land_timeout_s "
        "takeoff_tolerance_m arm_timeout_s arm_retry_s mode_timeout_s formation_check response "
        "link_delay_s initial_mass go_to_start max_data_age_s timesync_period_s predict "
        "velocity_from_position_s scheduling",
    )
    geofence = None
    g = node.child("geofence")
    if not g.absent:
        g.keys("min_enu_m max_enu_m")
        geofence = GeofenceConfig(g.child("min_enu_m").vec3(), g.child("max_enu_m").vec3())
        for k, axis in enumerate("xyz"):
            if not geofence.min_enu_m[k] < geofence.max_enu_m[k]:
                g.child("max_enu_m").fail(
                    f"expected max > min on every axis, got {axis}: min "
                    f"{geofence.min_enu_m[k]!r} >= max {geofence.max_enu_m[k]!r}"
                )
    fly = FlyConfig(
        control_mode=fly_mode(node.child("mode").string(d.control_mode, FLY_MODES)),
        rates=_fly_mode(node.child("rates"), d.rates),
        actuators=_fly_mode(node.child("actuators"), d.actuators),
        attitude=_fly_mode(node.child("attitude"), d.attitude),
        position=_position_mode(node.child("position"), d.position),
        heading=_heading(node.child("heading")),
        start=node.child("start").string(d.start, FLY_STARTS),
        takeoff_altitude_m=node.child("takeoff_altitude_m").number(
            d.takeoff_altitude_m, ge=0.5, le=1000.0
        ),
        end_action=FlyAction(node.child("end_action").string(d.end_action, FLY_ACTIONS)),
        abort_action=FlyAction(node.child("abort_action").string(d.abort_action, FLY_ACTIONS)),
        link_loss_action=FlyAction(
            node.child("link_loss_action").string(d.link_loss_action, FLY_ACTIONS)),
        stale_after_s=node.child("stale_after_s").number(d.stale_after_s, gt=0.0),
        link_lost_after_s=node.child("link_lost_after_s").number(d.link_lost_after_s, gt=0.0),
        link_timeout_s=node.child("link_timeout_s").number(d.link_timeout_s, gt=0.0),
        max_data_age_s=node.child("max_data_age_s").number(d.max_data_age_s, gt=0.0, le=10.0),
        timesync_period_s=node.child("timesync_period_s").number(d.timesync_period_s, ge=0.0,
                                                                 le=60.0),
        predict=node.child("predict").boolean(d.predict),
        velocity_from_position_s=node.child("velocity_from_position_s").number(
            d.velocity_from_position_s, ge=0.0, le=60.0),
        scheduling=node.child("scheduling").string(d.scheduling, FLY_SCHEDULING),
        max_tilt_rad=node.child("max_tilt_rad").number(d.max_tilt_rad, gt=0.0, le=math.pi),
        geofence=geofence,
        log_rate_hz=node.child("log_rate_hz").number(d.log_rate_hz, gt=0.0),
        connect_timeout_s=node.child("connect_timeout_s").number(d.connect_timeout_s, gt=0.0),
        takeoff_timeout_s=node.child("takeoff_timeout_s").number(d.takeoff_timeout_s, gt=0.0),
        land_timeout_s=node.child("land_timeout_s").number(d.land_timeout_s, gt=0.0),
        takeoff_tolerance_m=node.child("takeoff_tolerance_m").number(
            d.takeoff_tolerance_m, gt=0.0),
        arm_timeout_s=node.child("arm_timeout_s").number(d.arm_timeout_s, gt=0.0),
        arm_retry_s=node.child("arm_retry_s").number(d.arm_retry_s, ge=0.1),
        mode_timeout_s=node.child("mode_timeout_s").number(d.mode_timeout_s, gt=0.0),
        formation_check=_formation_check(node.child("formation_check"), d.formation_check),
        response=_response(node.child("response")),
        link_delay_s=node.child("link_delay_s").number(d.link_delay_s, ge=0.0, le=1.0),
        initial_mass=node.child("initial_mass").string(d.initial_mass, FLY_INITIAL_MASSES),
        go_to_start=_go_to_start(node.child("go_to_start"), d.go_to_start),
    )
    if not fly.takeoff_tolerance_m < fly.takeoff_altitude_m:
        node.child("takeoff_tolerance_m").fail(
            f"expected < takeoff_altitude_m {fly.takeoff_altitude_m!r}, got "
            f"{fly.takeoff_tolerance_m!r}")
    if not fly.link_lost_after_s > fly.stale_after_s:
        node.child("link_lost_after_s").fail(
            f"expected > stale_after_s {fly.stale_after_s!r}, got {fly.link_lost_after_s!r}"
        )
    for name in FLY_CONTROL_MODES:
        rate = fly.tick_rate_hz(name)
        if whole_ratio(rate, fly.log_rate_hz) is None:
            node.child("log_rate_hz").fail(
                f"must divide fly.{name}.tick_rate_hz {rate:g} (a whole number of ticks per "
                f"sample), got {fly.log_rate_hz:g}"
            )
    return fly
