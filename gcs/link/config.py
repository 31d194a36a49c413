"""Per-vehicle link settings (addresses, ids, timeouts, signing) and team-level id checks."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

from gcs.link.codec import GCS_COMPID, GCS_SYSID

PX4_SITL_GCS_PORT_BASE = 14540  # the GCS listens here (+ instance)
PX4_SITL_VEHICLE_PORT_BASE = 14580  # the vehicle listens here (+ instance)
#: PX4 SITL instances above 9 all send to 14549, so one GCS port per vehicle cannot work.
PX4_SITL_MAX_INSTANCE = 9


@dataclass(frozen=True, slots=True)
class VehicleLinkConfig:
    """How the GCS talks to one vehicle. Ports are UDP on ``local_host``/``remote_host``.

    ``remote_port=None`` requires ``learn_remote=True``: the GCS then answers whoever sent the
    first valid packet carrying this vehicle's sysid.
    """

    vehicle_id: int  # the team file's vehicle id, used in every message about this vehicle
    sysid: int
    local_port: int  # 0: any free port (tests)
    remote_port: int | None = None
    remote_host: str = "127.0.0.1"
    local_host: str = "127.0.0.1"
    compid: int = 1  # MAV_COMP_ID_AUTOPILOT1
    learn_remote: bool = False
    gcs_sysid: int = GCS_SYSID
    gcs_compid: int = GCS_COMPID
    heartbeat_period_s: float = 1.0  # GCS HEARTBEAT period
    # no valid message from the vehicle (any type) for this long -> LOST; 3 s keeps a vehicle that
    # sends only its 1 Hz HEARTBEAT (ArduPilot before its streams are asked for) ALIVE through
    # two lost beats (MAVSDK uses 3 s too)
    link_timeout_s: float = 3.0
    # no HEARTBEAT for this long while other messages arrive: logged (armed state and mode are
    # then stale); not LOST, since every message counts for liveness
    # (5 s: five 1 Hz periods; PX4 and ArduPilot keep HEARTBEAT at 1 Hz)
    heartbeat_timeout_s: float = 5.0
    # TIMESYNC requests for the round trip (gcs.link.clock); 0: none. On a shared port one
    # request per period reaches every vehicle behind one address, and all use its replies.
    timesync_period_s: float = 0.5
    # a vehicle heard before that sends nothing at all while a command waits for its ACK is
    # alive but busy (a program compiling or starting, a paused process), not refusing: the
    # command waits this long for it to speak, then asks again; 0: fail after the retries
    silent_wait_s: float = 30.0
    signing_key: bytes | None = None  # 32 bytes enables MAVLink 2 signing on this link
    signing_link_id: int = 0
    allow_unsigned: bool = False  # with a key: also accept unsigned packets

    def __post_init__(self) -> None:
        where = f"vehicle {self.vehicle_id} link"
        _check(1 <= self.sysid <= 255, f"{where}: sysid: expected 1..255, got {self.sysid}")
        _check(self.sysid != self.gcs_sysid,
               f"{where}: sysid: {self.sysid} equals the GCS sysid {self.gcs_sysid}")
        _check(0 <= self.compid <= 255, f"{where}: compid: expected 0..255, got {self.compid}")
        _check(0 <= self.local_port <= 65535,
               f"{where}: local_port: expected 0..65535, got {self.local_port}")
        if self.remote_port is None:
            _check(self.learn_remote,
                   f"{where}: remote_port: missing (set it, or set learn_remote: true)")
        else:
            _check(1 <= self.remote_port <= 65535,
                   f"{where}: remote_port: expected 1..65535, got {self.remote_port}")
        for key in ("heartbeat_period_s", "link_timeout_s", "heartbeat_timeout_s"):
            value = getattr(self, key)
            _check(value > 0.0, f"{where}: {key}: expected > 0, got {value}")
        _check(self.silent_wait_s >= 0.0,
               f"{where}: silent_wait_s: expected >= 0, got {self.silent_wait_s}")
        _check(self.timesync_period_s >= 0.0,
               f"{where}: timesync_period_s: expected >= 0, got {self.timesync_period_s}")
        if self.signing_key is not None:
            _check(len(self.signing_key) == 32,
                   f"{where}: signing_key: expected 32 bytes, got {len(self.signing_key)}")

    @property
    def remote(self) -> tuple[str, int] | None:
        return None if self.remote_port is None else (self.remote_host, self.remote_port)

    @property
    def name(self) -> str:
        """'vehicle 2 (sysid 3)', the prefix of every message about this vehicle."""
        return f"vehicle {self.vehicle_id} (sysid {self.sysid})"

    @classmethod
    def px4_sitl(cls, instance: int, **overrides: Any) -> VehicleLinkConfig:
        """PX4 SITL instance i's offboard link: GCS 14540+i, vehicle 14580+i, sysid = id = i+1."""
        if not 0 <= instance <= PX4_SITL_MAX_INSTANCE:
            raise ValueError(
                f"PX4 SITL instance {instance}: instances above {PX4_SITL_MAX_INSTANCE} all send "
                f"to port {PX4_SITL_GCS_PORT_BASE + PX4_SITL_MAX_INSTANCE}; give explicit ports"
            )
        base = cls(vehicle_id=instance + 1, sysid=instance + 1,
                   local_port=PX4_SITL_GCS_PORT_BASE + instance,
                   remote_port=PX4_SITL_VEHICLE_PORT_BASE + instance)
        return replace(base, **overrides)


def check_unique_sysids(configs: Iterable[VehicleLinkConfig]) -> None:
    """Raise ValueError naming every duplicated sysid (ground stations would merge them).

    Vehicles may share a local port (a `gcs.link.port.MavlinkPort` tells them apart by sysid),
    so the sysids must be unique across the team, not just per port."""
    by_sysid: dict[int, list[int]] = {}
    for c in configs:
        by_sysid.setdefault(c.sysid, []).append(c.vehicle_id)
    problems = [f"sysid {s} used by vehicles {v}" for s, v in by_sysid.items() if len(v) > 1]
    if problems:
        raise ValueError("team links: " + "; ".join(problems))


def shared_ports(configs: Iterable[VehicleLinkConfig]) -> dict[tuple[str, int], list[int]]:
    """(local_host, local_port) -> vehicle ids, for the nonzero ports more than one vehicle uses
    (port 0 is a new free port for each)."""
    by_port: dict[tuple[str, int], list[int]] = {}
    for c in configs:
        if c.local_port != 0:
            by_port.setdefault((c.local_host, c.local_port), []).append(c.vehicle_id)
    return {a: ids for a, ids in by_port.items() if len(ids) > 1}


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(message)
