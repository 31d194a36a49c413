"""Autopilot personalities: what makes an emulated vehicle behave like PX4, ArduPilot or the
paper's nominal model, where a ground station can notice.

A personality is chosen per vehicle (team file ``emulator.autopilot`` or
``vehicles[].emulator.autopilot``; ``vehicle-emu --autopilot`` overrides both). It bundles

* ``protocol``: the MAVLink face (HEARTBEAT autopilot type, reported firmware version, which
  setpoint messages are honoured, the ACK pattern, arming readiness after boot, whether the local
  frame is the vehicle's own EKF origin);
* ``dynamics``: the onboard inner loops as fitted to the recorded SITL responses (docs/emulator.md,
  "Calibration");
* ``sensors``: telemetry noise as fitted to the recorded hover.

``nominal`` is not an autopilot: it is the paper's nominal model behind PX4's protocol as of
v1.13 (actuator setpoints honoured), with noise-free telemetry, stiff inner loops and the team's
shared origin, for reproducing the paper's figures over MAVLink. ``px4`` (the default) is PX4
v1.16.0 SITL (SIH) as recorded; ``ardupilot`` is ArduCopter 4.7.0-dev SITL as recorded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "AUTOPILOT_NAMES",
    "DEFAULT_AUTOPILOT",
    "Dynamics",
    "PERSONALITIES",
    "Personality",
    "Protocol",
    "Sensors",
    "personality_of",
]

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12


@dataclass(frozen=True, slots=True)
class Protocol:
    """The MAVLink face of an autopilot."""

    family: str  # "px4" | "ardupilot": which mode table and command rules apply
    mav_autopilot: int  # HEARTBEAT.autopilot
    version: tuple[int, int, int]  # AUTOPILOT_VERSION.flight_sw_version (major, minor, patch)
    actuator_setpoints: bool  # SET_ACTUATOR_CONTROL_TARGET honoured (PX4 <= 1.13 only)
    ack_twice: bool  # default of EMU_ACK_TWICE (PX4 v1.16.0 answers DO_SET_MODE twice)
    arming_ready_s: float  # a vehicle booted on the ground refuses to arm before this [s]
    own_origin: bool  # LOCAL_POSITION_NED relative to the vehicle's own EKF origin
    param_defaults: tuple[tuple[str, float], ...] = ()  # parameter defaults as recorded
    statustext_end: str = ""  # appended to every STATUSTEXT (PX4 v1.16.0 ends each in a TAB)

    @property
    def version_word(self) -> int:
        """AUTOPILOT_VERSION.flight_sw_version: major << 24 | minor << 16 | patch << 8 | 255
        (255: release build)."""
        major, minor, patch = self.version
        return (major << 24) | (minor << 16) | (patch << 8) | 255


@dataclass(frozen=True, slots=True)
class Dynamics:
    """Onboard inner loops (see inner.py): placeholder until the calibration lands."""

    name: str = "nominal"


@dataclass(frozen=True, slots=True)
class Sensors:
    """Telemetry noise (1 sigma, white unless stated), applied when EMU_NOISE = 1."""

    position_std_m: float = 0.01
    velocity_std_mps: float = 0.02
    attitude_std_rad: float = 0.002
    gyro_std_radps: tuple[float, float, float] = (0.003, 0.003, 0.003)
    accel_std_mps2: tuple[float, float, float] = (0.05, 0.05, 0.05)


@dataclass(frozen=True, slots=True)
class Personality:
    """One autopilot personality (see the module docstring)."""

    name: str
    protocol: Protocol
    dynamics: Dynamics = field(default_factory=Dynamics)
    sensors: Sensors = field(default_factory=Sensors)


PERSONALITIES: dict[str, Personality] = {
    "nominal": Personality(
        "nominal",
        Protocol("px4", MAV_AUTOPILOT_PX4, (1, 13, 3), actuator_setpoints=True, ack_twice=True,
                 arming_ready_s=0.0, own_origin=False),
    ),
    "px4": Personality(
        "px4",
        # arming: refused until 3.0 s after the first HEARTBEAT (boot 1.36 s, armed at 4.36 s)
        # COM_RC_IN_MODE 4 (no manual control), as the recordings and the team's SITL runs set
        # it: Position and Altitude then descend at MPC_Z_VEL_MAX_DN (1.04 m/s recorded after
        # the offboard-loss failsafe) instead of holding
        Protocol("px4", MAV_AUTOPILOT_PX4, (1, 16, 0), actuator_setpoints=False, ack_twice=True,
                 arming_ready_s=3.0, own_origin=True, param_defaults=(("COM_RC_IN_MODE", 4),),
                 statustext_end="\t"),
    ),
    "ardupilot": Personality(
        "ardupilot",
        # arming in GUIDED: "Need Position Estimate" until the EKF uses GPS (41-42 s after
        # start; 23 s in STABILIZE); the ardupilot protocol work sets its own readiness timeline
        Protocol("ardupilot", MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), actuator_setpoints=False,
                 ack_twice=False, arming_ready_s=0.0, own_origin=True),
    ),
}
AUTOPILOT_NAMES = tuple(PERSONALITIES)
DEFAULT_AUTOPILOT = "px4"


def personality_of(name: str) -> Personality:
    """The personality called ``name``; ValueError naming the known ones otherwise."""
    try:
        return PERSONALITIES[name]
    except KeyError:
        raise ValueError(
            f"unknown autopilot {name!r}; expected one of {', '.join(AUTOPILOT_NAMES)}"
        ) from None
