"""The team file's optional `fly:` section (how `gcs fly` flies the team) -> FlyConfig, and the
check of the start positions that `gcs fly` makes before a go-to-start phase."""

from __future__ import annotations

from gcs.config.declare import read_section
from gcs.config.fly_schema import FlyConfig
from gcs.config.modes import FLY_CONTROL_MODES
from gcs.config.schema import ConfigError, TeamConfig, whole_ratio
from gcs.config.yamlnode import Node


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


def read_fly(node: Node) -> FlyConfig:
    """The optional `fly:` section (every key optional; the keys, their defaults and bounds are
    FlyConfig's declarations; see docs/configuration.md), with the rules between its keys."""
    fly = read_section(node, FlyConfig, FlyConfig())
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
