"""Vehicle specs from a team YAML (only the keys the emulator needs) or sensible defaults.

The emulator is an independent peer of the ground station, so it reads the team file itself with
pyyaml (it never imports ``gcs``). The reader is tolerant: keys it does not use are ignored; a key
it uses with a wrong type or value raises ``TeamFileError`` naming the key path, e.g.
``vehicles[2].plant.mass_kg: expected > 0, got -1.0``.

Keys read: ``sim.plant_rate_hz``; ``frame.origin`` (the team frame's origin on the globe:
GLOBAL_POSITION_INT, HOME_POSITION, GPS_GLOBAL_ORIGIN); ``vehicles[].id / sysid / initial /
airframe / plant / link``; top-level ``faults`` (``{kind, vehicle, at_s, ...}``);
``emulator.autopilot / origin / autopilot_params`` and ``vehicles[].emulator.autopilot /
origin_enu_m / boot_position_enu_m / autopilot_params`` (personality.py; ``autopilot_params``:
the parameters the real vehicles were booted with, checked against the personality's table,
a vehicle's names over the team's). Positions
are ENU metres, z up. A vehicle boots at ``emulator.boot_position_enu_m`` when given (e.g. on the
ground, away from the team file's start position, which a ground station then flies it to), else
at ``initial.position_enu_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from flightkit.physics import TABLE_I
from vehicle_emulator.config.params import ParamError, ParamStore, param_table
from vehicle_emulator.config.personality import (
    AUTOPILOT_NAMES,
    DEFAULT_AUTOPILOT,
    personality_of,
)

__all__ = [
    "DEFAULT_AIRFRAMES",
    "FaultSpec",
    "LinkSpec",
    "TeamFileError",
    "TeamSpec",
    "VehicleSpec",
    "default_vehicle",
    "load_team",
    "parse_team",
]

FAULT_KINDS = ("mass_drop", "link_loss", "packet_loss", "motor_efficiency")
JITTER_KINDS = ("uniform", "normal")  # packet_loss jitter distributions (faults.py)
ORIGIN_KINDS = ("own", "shared")

# Arm length, anti-torque coefficient and rotor limit per Table I airframe (the values of
# configs/square4.yaml), used when no team file is given.
DEFAULT_AIRFRAMES: tuple[tuple[float, float, float], ...] = (
    (0.20, 0.016, 6.0),
    (0.25, 0.016, 8.0),
    (0.12, 0.016, 3.0),
    (0.35, 0.016, 20.0),
)


class TeamFileError(ValueError):
    """A key the emulator reads has a wrong shape or value; the message names the key path."""


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """UDP addresses of one vehicle's API link: (host, port) pairs; None: the PX4 SITL default."""

    bind: tuple[str, int] | None = None
    remote: tuple[str, int] | None = None


@dataclass(frozen=True, slots=True)
class VehicleSpec:
    """One vehicle: identity, true plant, airframe and initial state (ENU world, FLU body)."""

    vehicle_id: int
    sysid: int
    mass_kg: float
    inertia_kgm2: tuple[float, float, float]
    arm_length_m: float
    anti_torque_m: float
    rotor_thrust_max_n: float
    motor_time_constant_s: float | None = None  # None: the personality's (plant.py)
    position_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_enu_rad: float = 0.0
    link: LinkSpec = field(default_factory=LinkSpec)
    autopilot: str = DEFAULT_AUTOPILOT  # personality name (personality.py)
    # EKF origin in the team frame; None: the personality decides (its own boot position below
    # the vehicle, or the team frame's origin for a personality without own origins)
    origin_enu_m: tuple[float, float, float] | None = None
    # parameters the vehicle boots with (``emulator.autopilot_params``), name -> value, in the
    # team file's order; applied after the personality's defaults
    autopilot_params: tuple[tuple[str, float], ...] = ()

    @property
    def starts_in_air(self) -> bool:
        """True when the initial position is above the ground plane (z > 0.05 m)."""
        return self.position_enu_m[2] > 0.05

    def local_origin_enu_m(self, own_origin: bool) -> tuple[float, float, float]:
        """Where this vehicle's LOCAL_POSITION_NED is zero, in the team frame: the configured
        origin, else (with ``own_origin``) the ground point below its boot position, else the
        team frame's origin."""
        if self.origin_enu_m is not None:
            return self.origin_enu_m
        if own_origin:
            return (self.position_enu_m[0], self.position_enu_m[1], 0.0)
        return (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class FaultSpec:
    """A scheduled fault; ``at_s`` counts on the fault clock (see faults.py). ``duration_s``:
    link_loss, how long the link is down; packet_loss, how long it lasts (0: the rest of the
    run)."""

    kind: str
    vehicle_id: int
    at_s: float
    fraction: float = 0.0
    duration_s: float = 0.0
    motor: int = 1
    efficiency: float = 1.0
    probability: float = 0.0
    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    jitter: str = "uniform"  # one of JITTER_KINDS
    reorder_probability: float = 0.0


@dataclass(frozen=True, slots=True)
class TeamSpec:
    """Everything the emulator reads from a team file."""

    name: str
    vehicles: tuple[VehicleSpec, ...]
    faults: tuple[FaultSpec, ...] = ()
    physics_rate_hz: float = 1000.0
    # the team frame's origin on the globe (lat deg, lon deg, alt m), ``frame.origin``; None:
    # not stated (the emulator's default, PX4 SITL's home)
    origin_lla: tuple[float, float, float] | None = None

    def vehicle(self, vehicle_id: int) -> VehicleSpec:
        """The vehicle with this id; KeyError naming the ids present otherwise."""
        for v in self.vehicles:
            if v.vehicle_id == vehicle_id:
                return v
        ids = [v.vehicle_id for v in self.vehicles]
        raise KeyError(f"team {self.name!r}: no vehicle with id {vehicle_id} (ids: {ids})")


def default_vehicle(vehicle_id: int, on_ground: bool = True) -> VehicleSpec:
    """Table I airframe ``min(N, 4)`` on the ground at the origin (or at 10 m if not on_ground)."""
    k = min(max(vehicle_id, 1), 4) - 1
    arm, anti, f_max = DEFAULT_AIRFRAMES[k]
    return VehicleSpec(
        vehicle_id=vehicle_id,
        sysid=vehicle_id,
        mass_kg=TABLE_I[k].mass_kg,
        inertia_kgm2=TABLE_I[k].inertia_kgm2,
        arm_length_m=arm,
        anti_torque_m=anti,
        rotor_thrust_max_n=f_max,
        position_enu_m=(0.0, 0.0, 0.0 if on_ground else 10.0),
    )


# --- tolerant typed getters ----------------------------------------------------------------------


def _get(d: Any, key: str, path: str) -> Any:
    if not isinstance(d, dict):
        raise TeamFileError(f"{path}: expected a mapping, got {type(d).__name__}")
    return d.get(key)


def _float(value: Any, path: str, *, positive: bool = False, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TeamFileError(f"{path}: expected a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise TeamFileError(f"{path}: expected a finite number, got {value!r}")
    if positive and x <= 0.0:
        raise TeamFileError(f"{path}: expected > 0, got {value!r}")
    if minimum is not None and x < minimum:
        raise TeamFileError(f"{path}: expected >= {minimum}, got {value!r}")
    return x


def _int(value: Any, path: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TeamFileError(f"{path}: expected an integer, got {value!r}")
    if not lo <= value <= hi:
        raise TeamFileError(f"{path}: expected {lo}..{hi}, got {value!r}")
    return int(value)


def _optional_float(section: Any, path: str, key: str, **kw: Any) -> float | None:
    value = _get(section, key, path)
    return None if value is None else _float(value, f"{path}.{key}", **kw)


def _vec3(value: Any, path: str, *, positive: bool = False) -> tuple[float, float, float]:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise TeamFileError(f"{path}: expected a list of 3 numbers, got {value!r}")
    x, y, z = (_float(v, f"{path}[{i}]", positive=positive) for i, v in enumerate(value))
    return (x, y, z)


def _address(value: Any, path: str) -> tuple[str, int]:
    """``"host:port"``, ``port`` or ``[host, port]`` -> (host, port)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return ("127.0.0.1", _int(value, path, 1, 65535))
    if isinstance(value, str) and ":" in value:
        host, _, port = value.rpartition(":")
        if port.isdigit():
            return (host or "127.0.0.1", _int(int(port), path, 1, 65535))
    if isinstance(value, list | tuple) and len(value) == 2 and isinstance(value[0], str):
        return (value[0], _int(value[1], f"{path}[1]", 1, 65535))
    raise TeamFileError(f"{path}: expected 'host:port' or a port number, got {value!r}")


def _autopilot(value: Any, path: str) -> str:
    if value not in AUTOPILOT_NAMES:
        raise TeamFileError(f"{path}: expected one of {', '.join(AUTOPILOT_NAMES)}, got {value!r}")
    return value


def _vehicle(raw: Any, index: int, team_emulator: dict[str, Any]) -> VehicleSpec:
    path = f"vehicles[{index}]"
    vid_raw = _get(raw, "id", path)
    if vid_raw is None:
        raise TeamFileError(f"{path}.id: missing")
    vid = _int(vid_raw, f"{path}.id", 1, 254)
    sysid_raw = _get(raw, "sysid", path)
    sysid = vid if sysid_raw is None else _int(sysid_raw, f"{path}.sysid", 1, 254)
    base = default_vehicle(vid)

    plant = _get(raw, "plant", path) or {}
    airframe = _get(raw, "airframe", path) or {}
    initial = _get(raw, "initial", path) or {}
    link = _get(raw, "link", path) or {}
    emulator = _get(raw, "emulator", path) or {}

    def opt(section: Any, name: str, key: str, default: float, **kw: Any) -> float:
        value = _get(section, key, f"{path}.{name}")
        return default if value is None else _float(value, f"{path}.{name}.{key}", **kw)

    inertia_raw = _get(plant, "inertia_kgm2", f"{path}.plant")
    inertia = (
        base.inertia_kgm2
        if inertia_raw is None
        else _vec3(inertia_raw, f"{path}.plant.inertia_kgm2", positive=True)
    )
    pos_raw = _get(initial, "position_enu_m", f"{path}.initial")
    pos_path = f"{path}.initial.position_enu_m"
    boot_raw = _get(emulator, "boot_position_enu_m", f"{path}.emulator")
    if boot_raw is not None:
        pos_raw, pos_path = boot_raw, f"{path}.emulator.boot_position_enu_m"
    vel_raw = _get(initial, "velocity_enu_mps", f"{path}.initial")

    # The team file describes the link from the ground station's side (local_port: where the
    # GCS listens; remote_host/remote_port: where it sends, i.e. where this vehicle binds).
    def port(key: str) -> int | None:
        value = _get(link, key, f"{path}.link")
        return None if value is None else _int(value, f"{path}.link.{key}", 1, 65535)

    remote_host = _get(link, "remote_host", f"{path}.link")
    if remote_host is not None and not isinstance(remote_host, str):
        raise TeamFileError(f"{path}.link.remote_host: expected a host name, got {remote_host!r}")
    bind_port, gcs_port = port("remote_port"), port("local_port")
    bind = None if bind_port is None else (remote_host or "127.0.0.1", bind_port)
    remote = None if gcs_port is None else ("127.0.0.1", gcs_port)

    rpy_raw = _get(initial, "attitude_rpy_rad", f"{path}.initial")
    rpy = (0.0, 0.0, 0.0) if rpy_raw is None else _vec3(rpy_raw, f"{path}.initial.attitude_rpy_rad")
    if rpy[0] != 0.0 or rpy[1] != 0.0:
        raise TeamFileError(
            f"{path}.initial.attitude_rpy_rad: the emulator starts level; roll and pitch "
            f"must be 0, got {rpy[0]!r}, {rpy[1]!r}"
        )

    return VehicleSpec(
        vehicle_id=vid,
        sysid=sysid,
        mass_kg=opt(plant, "plant", "mass_kg", base.mass_kg, positive=True),
        inertia_kgm2=inertia,
        arm_length_m=opt(airframe, "airframe", "arm_length_m", base.arm_length_m, positive=True),
        anti_torque_m=opt(airframe, "airframe", "anti_torque_m", base.anti_torque_m, positive=True),
        rotor_thrust_max_n=opt(
            airframe, "airframe", "rotor_thrust_max_n", base.rotor_thrust_max_n, positive=True
        ),
        motor_time_constant_s=_optional_float(
            airframe, f"{path}.airframe", "motor_time_constant_s", minimum=0.0
        ),
        position_enu_m=(
            base.position_enu_m
            if pos_raw is None
            else _vec3(pos_raw, pos_path)
        ),
        velocity_enu_mps=(
            (0.0, 0.0, 0.0)
            if vel_raw is None
            else _vec3(vel_raw, f"{path}.initial.velocity_enu_mps")
        ),
        yaw_enu_rad=rpy[2],
        link=LinkSpec(bind=bind, remote=remote),
        **_emulator_keys(emulator, f"{path}.emulator", team_emulator),
    )


def _emulator_keys(
    section: Any, path: str, team_emulator: dict[str, Any]
) -> dict[str, Any]:
    """``autopilot``, ``origin_enu_m`` and ``autopilot_params`` of a vehicle from its own and
    the team's ``emulator:`` sections (the vehicle's win)."""
    autopilot = _get(section, "autopilot", path)
    if autopilot is None:
        autopilot = team_emulator["autopilot"]
    else:
        autopilot = _autopilot(autopilot, f"{path}.autopilot")
    origin_raw = _get(section, "origin_enu_m", path)
    if origin_raw is not None:
        origin = _vec3(origin_raw, f"{path}.origin_enu_m")
    elif team_emulator["origin"] == "shared":
        origin = (0.0, 0.0, 0.0)
    else:
        origin = None
    # the team's names apply to the vehicles whose personality has them (a mixed team); a
    # vehicle's own names must all be its personality's
    names = _param_names(autopilot)
    params = {k: v for k, v in team_emulator["autopilot_params"].items() if k in names}
    own = _autopilot_params(_get(section, "autopilot_params", path), f"{path}.autopilot_params")
    for name, value in own.items():
        key = f"{path}.autopilot_params.{name}"
        if name not in names:
            raise TeamFileError(_unknown_param(key, autopilot, name))
        _check_param_value(key, autopilot, name, value)
    for name, value in params.items():
        _check_param_value(f"emulator.autopilot_params.{name}", autopilot, name, value)
    params.update(own)
    return {"autopilot": autopilot, "origin_enu_m": origin,
            "autopilot_params": tuple(params.items())}


def _autopilot_params(raw: Any, path: str) -> dict[str, float]:
    """An ``autopilot_params`` mapping: parameter name -> number."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise TeamFileError(f"{path}: expected a mapping of parameter names to numbers, "
                            f"got {raw!r}")
    out: dict[str, float] = {}
    for name, value in raw.items():
        if not isinstance(name, str) or not name:
            raise TeamFileError(f"{path}: expected parameter names, got {name!r}")
        out[name] = _float(value, f"{path}.{name}")
    return out


def _param_names(autopilot: str) -> frozenset[str]:
    return frozenset(p.name for p in param_table(personality_of(autopilot).protocol.family))


def _check_param_value(path: str, autopilot: str, name: str, value: float) -> None:
    store = ParamStore.for_family(personality_of(autopilot).protocol.family)
    try:
        store.set(name, value)
    except ParamError as exc:
        raise TeamFileError(f"{path}: {exc}") from None


def _unknown_param(path: str, autopilot: str, name: str) -> str:
    return (f"{path}: the {autopilot} personality has no parameter {name!r} (docs/emulator.md, "
            "Parameters)")


def _team_emulator(raw: Any) -> dict[str, Any]:
    """The top-level ``emulator:`` section: default personality and origin rule."""
    section = raw.get("emulator") or {}
    if not isinstance(section, dict):
        raise TeamFileError(f"emulator: expected a mapping, got {section!r}")
    autopilot = section.get("autopilot")
    origin = section.get("origin", "own")
    if origin not in ORIGIN_KINDS:
        raise TeamFileError(f"emulator.origin: expected one of {', '.join(ORIGIN_KINDS)}, "
                            f"got {origin!r}")
    params = _autopilot_params(section.get("autopilot_params"), "emulator.autopilot_params")
    return {
        "autopilot": DEFAULT_AUTOPILOT
        if autopilot is None
        else _autopilot(autopilot, "emulator.autopilot"),
        "origin": origin,
        "autopilot_params": params,
    }


def _fault(raw: Any, index: int, vehicle_ids: set[int]) -> FaultSpec:
    path = f"faults[{index}]"
    kind = _get(raw, "kind", path)
    if kind not in FAULT_KINDS:
        raise TeamFileError(f"{path}.kind: expected one of {FAULT_KINDS}, got {kind!r}")
    vid_raw = _get(raw, "vehicle", path)
    vid = _int(vid_raw, f"{path}.vehicle", 1, 254) if vid_raw is not None else -1
    if vid not in vehicle_ids:
        raise TeamFileError(f"{path}.vehicle: no vehicle with id {vid_raw!r} in the team")
    at_raw = _get(raw, "at_s", path)
    at_s = 0.0 if at_raw is None else _float(at_raw, f"{path}.at_s", minimum=0.0)

    def num(key: str, default: float, lo: float, hi: float) -> float:
        value = _get(raw, key, path)
        if value is None:
            return default
        x = _float(value, f"{path}.{key}")
        if not lo <= x <= hi:
            raise TeamFileError(f"{path}.{key}: expected {lo}..{hi}, got {value!r}")
        return x

    motor_raw = _get(raw, "motor", path)
    jitter = _get(raw, "jitter", path)
    if jitter is None:
        jitter = "uniform"
    elif jitter not in JITTER_KINDS:
        raise TeamFileError(
            f"{path}.jitter: expected one of {', '.join(JITTER_KINDS)}, got {jitter!r}"
        )
    return FaultSpec(
        kind=kind,
        vehicle_id=vid,
        at_s=at_s,
        fraction=num("fraction", 0.0, 0.0, 0.95),
        duration_s=num("duration_s", 0.0, 0.0, 1e6),
        motor=1 if motor_raw is None else _int(motor_raw, f"{path}.motor", 1, 4),
        efficiency=num("efficiency", 1.0, 0.0, 1.0),
        probability=num("probability", 0.0, 0.0, 1.0),
        latency_ms=num("latency_ms", 0.0, 0.0, 10000.0),
        jitter_ms=num("jitter_ms", 0.0, 0.0, 10000.0),
        jitter=jitter,
        reorder_probability=num("reorder_probability", 0.0, 0.0, 1.0),
    )


def parse_team(raw: Any, name: str = "team") -> TeamSpec:
    """Build a TeamSpec from already-loaded YAML data; TeamFileError on a bad key."""
    if not isinstance(raw, dict):
        raise TeamFileError(f"{name}: expected a mapping at the top level")
    vehicles_raw = raw.get("vehicles")
    if not isinstance(vehicles_raw, list) or not vehicles_raw:
        raise TeamFileError("vehicles: expected a non-empty list")
    team_emulator = _team_emulator(raw)
    vehicles = tuple(_vehicle(v, i, team_emulator) for i, v in enumerate(vehicles_raw))
    for name in team_emulator["autopilot_params"]:
        if not any(name in _param_names(v.autopilot) for v in vehicles):
            autopilots = "/".join(sorted({v.autopilot for v in vehicles}))
            raise TeamFileError(_unknown_param(f"emulator.autopilot_params.{name}", autopilots,
                                               name))
    ids = [v.vehicle_id for v in vehicles]
    sysids = [v.sysid for v in vehicles]
    if len(set(ids)) != len(ids):
        raise TeamFileError(f"vehicles: duplicate id in {ids}")
    if len(set(sysids)) != len(sysids):
        raise TeamFileError(f"vehicles: duplicate sysid in {sysids} (ground stations would merge)")
    faults_raw = raw.get("faults") or []
    if not isinstance(faults_raw, list):
        raise TeamFileError("faults: expected a list")
    faults = tuple(_fault(f, i, set(ids)) for i, f in enumerate(faults_raw))
    sim = raw.get("sim") or {}
    rate_raw = _get(sim, "plant_rate_hz", "sim")
    rate = 1000.0 if rate_raw is None else _float(rate_raw, "sim.plant_rate_hz", positive=True)
    team_name = raw.get("name") if isinstance(raw.get("name"), str) else name
    return TeamSpec(name=team_name, vehicles=vehicles, faults=faults, physics_rate_hz=rate,
                    origin_lla=_frame_origin(raw.get("frame")))


def _frame_origin(frame: Any) -> tuple[float, float, float] | None:
    """``frame.origin``: [lat deg, lon deg, alt m] of the team frame's origin, or None."""
    if frame is None:
        return None
    raw = _get(frame, "origin", "frame")
    if raw is None:
        return None
    lat, lon, alt = _vec3(raw, "frame.origin")
    for value, limit, what in ((lat, 90.0, "latitude"), (lon, 180.0, "longitude")):
        if abs(value) > limit:
            raise TeamFileError(f"frame.origin: {what} {value!r} outside -{limit}..{limit} deg")
    return (lat, lon, alt)


def load_team(path: str | Path) -> TeamSpec:
    """Read a team YAML file; TeamFileError (with the file name) on a bad key."""
    p = Path(path)
    try:
        raw = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise TeamFileError(f"{p}: not valid YAML: {exc}") from exc
    try:
        return parse_team(raw, name=p.stem)
    except TeamFileError as exc:
        raise TeamFileError(f"{p}: {exc}") from exc
