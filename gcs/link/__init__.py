"""MAVLink link layers: sans-IO codec, UDP endpoint, shared port, per-vehicle proxy, tlog writer."""

from gcs.link.codec import CodecStats, MavlinkCodec
from gcs.link.commands import CommandNotConfirmedError, CommandRejectedError, CommandTimeoutError
from gcs.link.config import VehicleLinkConfig, check_unique_sysids
from gcs.link.enums import LinkState, MavResult
from gcs.link.fastpath import HotTable
from gcs.link.port import MavlinkPort, PortStats
from gcs.link.proxy import LinkStats, VehicleProxy
from gcs.link.setpoints import SetpointError
from gcs.link.telemetry import Clock, MonotonicClock, VehicleState
from gcs.link.tlog import TlogWriter
from gcs.link.udp import LinkClosedError, UdpEndpoint

__all__ = [
    "Clock",
    "CodecStats",
    "CommandNotConfirmedError",
    "CommandRejectedError",
    "CommandTimeoutError",
    "HotTable",
    "LinkClosedError",
    "LinkState",
    "LinkStats",
    "MavResult",
    "MavlinkCodec",
    "MavlinkPort",
    "MonotonicClock",
    "PortStats",
    "SetpointError",
    "TlogWriter",
    "UdpEndpoint",
    "VehicleLinkConfig",
    "VehicleProxy",
    "VehicleState",
    "check_unique_sysids",
]
