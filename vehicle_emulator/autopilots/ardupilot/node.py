"""The ArduPilot personality on the wire: the messages and commands of one ``ardupilot`` vehicle.

``ArduPilotNode`` is the VehicleNode (../node.py) of a vehicle whose personality's protocol family
is ``ardupilot``, around the pure ArduCopter state machine (logic.py); what it reproduces is
ArduCopter 4.7.0-dev SITL as recorded (docs/emulator.md, "ArduPilot personality"):

* Streams: nothing but HEARTBEAT (1 Hz) and ArduPilot's own TIMESYNC request every 10 s until
  asked (``DEFAULT_RATES_HZ``). SET_MESSAGE_INTERVAL is ACCEPTED for every stream ArduPilot maps
  to a message of its own, HEARTBEAT included; DENIED with "No ap_message for mavlink id (N)" for
  one it does not map (TIMESYNC, ODOMETRY). GET_MESSAGE_INTERVAL: the interval, -1 when off;
  0 and FAILED for an unmapped id. LOCAL_POSITION_NED only once the EKF has a position.
  REQUEST_DATA_STREAM (MAVProxy's way) sets ArduCopter's stream groups (``DATA_STREAM_GROUPS``).
* One COMMAND_ACK per command; the SET_MODE message is acknowledged as command 11 (ArduPilot's
  quirk); an accepted mode change sends an extra HEARTBEAT at once (on the next tick).
* STATUSTEXT up to 50 bytes, never chunked. Parameters: ArduCopter's names, integers cast to
  float. HOME_POSITION and GPS_GLOBAL_ORIGIN when the EKF origin is set and at each arming.
* A plain-text boot banner (EMU_BANNER) on each link before the first packet.
* SET_POSITION_TARGET_GLOBAL_INT in GUIDED: latitude/longitude (WGS-84) and an altitude above
  mean sea level (frames GLOBAL, GLOBAL_INT) or above home (GLOBAL_RELATIVE_ALT[_INT]), flown like
  the local target it amounts to; terrain frames and invalid coordinates stop the vehicle.

Links: ArduPilot SITL's ``udpclient`` sends from an ephemeral port, new for each process, and
hears only its peer; runner.py / command.py open such a link unless a bind is forced (``--bind``).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from vehicle_emulator.autopilots.ardupilot.logic import (
    MSG_GPS_GLOBAL_ORIGIN,
    MSG_HOME_POSITION,
    ArduCopter,
    CopterObservation,
)
from vehicle_emulator.autopilots.ardupilot.modes import Mode
from vehicle_emulator.autopilots.ardupilot.targets import (
    guided_attitude_target,
    guided_position_target,
)
from vehicle_emulator.autopilots.demand import MavResult, Severity
from vehicle_emulator.autopilots.node import Link, VehicleNode, _int
from vehicle_emulator.autopilots.setpoints import (
    MAV_FRAME_LOCAL_NED,
    POS_IGNORE_BITS,
    PositionTargetFields,
)
from vehicle_emulator.mavlink.codec import mavlink
from vehicle_emulator.mavlink.telemetry import DEFAULT_RATES_HZ as PX4_RATES_HZ
from vehicle_emulator.physics import frames, geodesy

log = logging.getLogger(__name__)

__all__ = ["ArduPilotNode", "BANNER", "DEFAULT_RATES_HZ"]

#: ArduCopter 4.7's defaults (SRx rates all 0): HEARTBEAT 1 Hz, its TIMESYNC request every 10 s.
DEFAULT_RATES_HZ: dict[str, float] = {
    **{name: 0.0 for name in PX4_RATES_HZ},
    "HEARTBEAT": 1.0,
    "TIMESYNC": 0.1,
}
#: MAVLink ids ArduPilot's mavlink_id_to_ap_message_id maps (the common ones; GCS_Common.cpp).
MAPPED_MSGIDS = frozenset({
    0, 1, 2, 22, 24, 26, 27, 29, 30, 31, 32, 33, 35, 36, 42, 46, 49, 62, 65, 74, 83, 85, 87,
    105, 116, 125, 129, 132, 136, 137, 147, 148, 152, 162, 163, 164, 165, 168, 173, 178, 193,
    194, 241, 242, 245, 435, 437,
})
MSG_SET_MODE = 11
#: ArduCopter's stream groups (GCS_Mavlink.cpp ``STREAM_*_msgs``) by MAV_DATA_STREAM id, with the
#: messages of each group the emulator sends (the others it does not emulate: RAW_IMU,
#: SCALED_PRESSURE, RC_CHANNELS, SERVO_OUTPUT_RAW, VFR_HUD, AHRS, SYSTEM_TIME, ...). Id 0 (ALL)
#: sets every group; PARAMS is never set by a request.
DATA_STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    1: (),  # RAW_SENSORS: RAW_IMU, SCALED_IMU2/3, SCALED_PRESSURE/2/3
    2: ("SYS_STATUS", "GPS_RAW_INT"),  # EXTENDED_STATUS (+ POWER_STATUS, MEMINFO, ...)
    3: (),  # RC_CHANNELS: SERVO_OUTPUT_RAW, RC_CHANNELS
    4: (),  # RAW_CONTROLLER: nothing on a copter
    6: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),  # POSITION
    10: ("ATTITUDE",),  # EXTRA1 (+ SIMSTATE, AHRS2, PID_TUNING)
    11: (),  # EXTRA2: VFR_HUD
    12: ("BATTERY_STATUS",),  # EXTRA3 (+ AHRS, SYSTEM_TIME, EKF_STATUS_REPORT, VIBRATION, ...)
}
MAV_DATA_STREAM_ALL = 0
#: Stand-in for SITL's plain-text banner: 164 bytes in 3 datagrams before the first packet, of
#: which the recording keeps only the version line (the text itself was not logged).
BANNER = (
    b"\n\nInit ArduCopter V4.7.0-dev (90700977)\n\n",
    b"Free RAM: 131072\n",
    b"vehicle-emu: ArduCopter SITL boot banner stand-in (plain text, not MAVLink)\n"
    b"------------------------------\n",
)
# AUTOPILOT_VERSION: MISSION_FLOAT | MISSION_INT | COMMAND_INT | SET_ATTITUDE_TARGET |
# SET_POSITION_TARGET_LOCAL_NED | SET_POSITION_TARGET_GLOBAL_INT | FLIGHT_TERMINATION |
# MAVLINK2 | PARAM_ENCODE_C_CAST
CAPABILITIES = 0x1 | 0x4 | 0x8 | 0x40 | 0x80 | 0x100 | 0x800 | 0x2000 | 0x20000
GLOBAL_AMSL_FRAMES = (0, 5)  # MAV_FRAME_GLOBAL, _GLOBAL_INT
GLOBAL_RELATIVE_FRAMES = (3, 6)  # MAV_FRAME_GLOBAL_RELATIVE_ALT, _RELATIVE_ALT_INT
FIRMWARE_TYPE_DEV = 0


class ArduPilotNode(VehicleNode):
    """VehicleNode with ArduCopter's handlers (module docstring); ``autopilot`` is an
    ``ardupilot.ArduCopter``."""

    __slots__ = ()
    autopilot: ArduCopter

    # --- state exchange ------------------------------------------------------------------------

    def observation(self, position: tuple[float, float, float],
                    velocity: tuple[float, float, float], yaw: float, on_ground: bool,
                    battery_remaining: float, tilt_cos: float) -> CopterObservation:
        return CopterObservation(position, velocity, yaw, on_ground, battery_remaining, tilt_cos)

    def position_ok(self, now_s: float) -> bool:
        """SYS_STATUS GPS bit: set from boot, as before (ArduCopter's own timeline not modelled)."""
        return True

    def base_mode_flags(self, now_s: float) -> int:
        return self.autopilot.base_mode(now_s) & 0x7F  # SAFETY_ARMED added per HEARTBEAT

    def landed_state(self) -> int:
        return self.autopilot.landed_state()

    def refresh_extra(self, now_s: float) -> None:
        i, ap, st = self.index, self.autopilot, self.status
        st.position_from_ms[i] = math.ceil(ap.boot.at(ap.boot.POSITION_S) * 1e3)
        st.vtol_state[i] = 3  # MAV_VTOL_STATE_MC, as ArduCopter reports it
        home = ap.home_enu_m  # ArduPilot sets home where it arms
        st.home_ned_m[i] = (home[1], home[0], -home[2])

    def announce_origin(self, now_s: float) -> None:
        """ArduPilot sends GPS_GLOBAL_ORIGIN when its EKF sets the origin (the boot timeline,
        drain_events), not PX4's once-after-boot."""

    def setpoint_driven(self) -> bool:
        return self.autopilot.setpoint_driven()

    def boot_banner(self) -> list[bytes]:
        return list(BANNER) if self.params.get_int("EMU_BANNER") else []

    # --- outputs -------------------------------------------------------------------------------

    def statustext(self, severity: Severity, text: str) -> None:
        """STATUSTEXT to all links: ArduPilot sends at most 50 bytes, never in chunks."""
        log.info("vehicle %d (sysid %d): %s", self.spec.vehicle_id, self.sysid, text)
        msg = mavlink.MAVLink_statustext_message(int(severity), text.encode()[:50], 0, 0)
        self.send_msg(msg)

    def drain_events(self, now_s: float | None = None) -> None:
        """The messages the autopilot asked for (GPS_GLOBAL_ORIGIN, HOME_POSITION), then its
        STATUSTEXTs (ArduPilot's order at arming)."""
        requests, self.autopilot.requests[:] = list(self.autopilot.requests), []
        t = self.plant.time_s if now_s is None else now_s
        for msgid in requests:
            self._send_requested(t, msgid, None, None)
        super().drain_events(now_s)

    def _ack_twice(self) -> bool:
        return False

    # --- commands ------------------------------------------------------------------------------

    def command(self, now_s: float, cmd: int, p: list[float], link: Link, addr: Any) -> MavResult:
        """ArduCopter's answers (module docstring, logic.py)."""
        ap, obs = self.autopilot, self.observe()
        if cmd == 400:  # COMPONENT_ARM_DISARM
            if p[0] not in (0.0, 1.0):
                return MavResult.UNSUPPORTED
            return ap.arm(now_s, obs, p[0] == 1.0, magic=_int(p[1]))
        if cmd == 176:  # DO_SET_MODE: param1 CUSTOM_MODE_ENABLED, param2 the mode number
            if not _int(p[0]) & 1:
                return MavResult.UNSUPPORTED
            return self._set_mode(now_s, _int(p[1], -1))
        if cmd == 21:  # NAV_LAND: the LAND mode
            return self._set_mode(now_s, int(Mode.LAND))
        if cmd == 22:  # NAV_TAKEOFF: param7 above home
            return ap.takeoff(now_s, obs, p[6])
        if cmd == 511:  # SET_MESSAGE_INTERVAL
            return self._set_message_interval(now_s, p)
        if cmd == 510:  # GET_MESSAGE_INTERVAL
            msgid = _int(p[0], -1)
            if msgid not in MAPPED_MSGIDS:
                self._send_interval(msgid, 0, link, addr)
                return MavResult.FAILED
            streamed = self._streamed(msgid)
            us = self.telemetry.interval_us(self.index, msgid) if streamed else -1
            self._send_interval(msgid, us, link, addr)
            return MavResult.ACCEPTED
        if cmd in (512, 520):  # REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES
            msgid = 148 if cmd == 520 else _int(p[0], -1)
            if msgid not in MAPPED_MSGIDS:
                return MavResult.FAILED
            return self._send_requested(now_s, msgid, link, addr)
        return MavResult.UNSUPPORTED  # INJECT_FAILURE included: ArduPilot has none

    def _set_mode(self, now_s: float, number: int) -> MavResult:
        """A mode command; an accepted change sends an extra HEARTBEAT at once."""
        ap = self.autopilot
        before = ap.mode
        result = ap.set_mode(now_s, self.observe(), number)
        if result is MavResult.ACCEPTED and ap.mode is not before:
            self.apply_demand()
            self.refresh_status(now_s)
            self.telemetry.next_due_s[self.index, self.telemetry.index["HEARTBEAT"]] = now_s
        return result

    def _on_set_mode(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """The SET_MODE message: ArduPilot answers with a COMMAND_ACK for "command" 11."""
        if msg.target_system not in (0, self.sysid):
            self.counters.other_target += 1
            return
        if msg.base_mode & 1:
            result = self._set_mode(now_s, int(msg.custom_mode))
        else:
            result = MavResult.UNSUPPORTED
        self._ack(MSG_SET_MODE, result, link, addr, msg)
        self.drain_events(now_s)

    def _on_request_data_stream(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """REQUEST_DATA_STREAM as GCS_Common.cpp's handle_request_data_stream: start_stop 1 sets
        the group's rate to req_message_rate Hz (every message of the group at 1000/rate ms),
        start_stop 0 or a rate of 0 stops the group, any other start_stop is ignored; no
        answer either way. Unknown stream ids change nothing."""
        if msg.target_system not in (0, self.sysid):
            self.counters.other_target += 1
            return
        if msg.start_stop not in (0, 1):
            return
        rate_hz = int(msg.req_message_rate) if msg.start_stop == 1 else 0
        stream = int(msg.req_stream_id)
        if stream == MAV_DATA_STREAM_ALL:
            names = [n for group in DATA_STREAM_GROUPS.values() for n in group]
        else:
            names = list(DATA_STREAM_GROUPS.get(stream, ()))
        # ArduPilot's interval is whole milliseconds: 1000 // rate
        interval_us = -1.0 if rate_hz <= 0 else max(1000 // rate_hz, 1) * 1e3
        for name in names:
            msgid = int(getattr(mavlink, f"MAVLINK_MSG_ID_{name}"))
            self.telemetry.set_interval(self.index, msgid, interval_us, now_s)

    def _streamed(self, msgid: int) -> bool:
        """ArduPilot maps it and the emulator streams it."""
        k = self.telemetry.msgids.get(msgid)
        return k is not None and msgid in MAPPED_MSGIDS

    def _set_message_interval(self, now_s: float, p: list[float]) -> MavResult:
        if not (math.isfinite(p[0]) and math.isfinite(p[1])):
            return MavResult.DENIED
        msgid = _int(p[0], -1)
        if msgid not in MAPPED_MSGIDS:
            self.statustext(Severity.INFO, f"No ap_message for mavlink id ({msgid})")
            return MavResult.DENIED
        if not self._streamed(msgid):
            return MavResult.UNSUPPORTED  # ArduPilot has it; the emulator does not send it
        self.telemetry.set_interval(self.index, msgid, p[1], now_s)
        return MavResult.ACCEPTED

    def _send_interval(self, msgid: int, interval_us: int, link: Link, addr: Any) -> None:
        msg = mavlink.MAVLink_message_interval_message(msgid & 0xFFFF, interval_us)
        self.send_msg(msg, link, addr)

    def _send_requested(self, now_s: float, msgid: int, link: Link | None, addr: Any
                        ) -> MavResult:
        ap = self.autopilot
        if msgid == 148:
            major, minor, patch = self.personality.protocol.version
            version = (major << 24) | (minor << 16) | (patch << 8) | FIRMWARE_TYPE_DEV
            msg = mavlink.MAVLink_autopilot_version_message(
                CAPABILITIES, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, self.sysid,
                [0] * 18,
            )
        elif msgid in (MSG_HOME_POSITION, MSG_GPS_GLOBAL_ORIGIN) and not ap.boot.origin_set(now_s):
            return MavResult.ACCEPTED  # ArduPilot: nothing to send before the EKF origin
        else:
            return super()._send_requested(now_s, msgid, link, addr)  # type: ignore[arg-type]
        self.send_msg(msg, link, addr)
        return MavResult.ACCEPTED

    # --- setpoints -----------------------------------------------------------------------------

    def _on_attitude_target(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """SET_ATTITUDE_TARGET as ArduCopter reads it (ardupilot_targets.py): used in GUIDED
        and GUIDED_NOGPS only."""
        if not self._for_me(msg):
            return
        ap = self.autopilot
        target = guided_attitude_target(
            msg.type_mask, msg.q, (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate),
            msg.thrust, bool(self.params.get_int("GUID_OPTIONS") & 8),
            self.params["WPNAV_SPEED_UP"] * 0.01, self.params["WPNAV_SPEED_DN"] * 0.01,
        )
        used = ap.on_attitude_target(now_s, self.observe(), target)
        self._count_target(target is not None, used, "attitude target")

    def _on_position_target_local(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """SET_POSITION_TARGET_LOCAL_NED as ArduCopter reads it: used in GUIDED only."""
        if not self._for_me(msg):
            return
        obs = self.observe()
        target, velocity_only = guided_position_target(
            PositionTargetFields.of(msg), self.local_origin_enu_m, obs.position_enu_m,
            obs.yaw_enu_rad,
        )
        used = self.autopilot.on_position_target(now_s, obs, target, velocity_only)
        self._count_target(target is not None, used, "position target")

    def _on_position_target_global(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT (module docstring): the same target in the vehicle's
        local NED frame, then ArduCopter's rules for it."""
        if not self._for_me(msg):
            return
        obs = self.observe()
        mask = int(msg.type_mask)
        pos_ned = (0.0, 0.0, 0.0)
        valid = True
        if not any(mask & b for b in POS_IGNORE_BITS):
            enu = self._team_enu_of_global(msg)
            valid = enu is not None
            if enu is not None:
                ned = frames.local_ned_from_enu(enu, self.local_origin_enu_m)
                pos_ned = (float(ned[0]), float(ned[1]), float(ned[2]))
        fields = PositionTargetFields(
            mask, MAV_FRAME_LOCAL_NED, pos_ned, (float(msg.vx), float(msg.vy), float(msg.vz)),
            (float(msg.afx), float(msg.afy), float(msg.afz)), float(msg.yaw),
            float(msg.yaw_rate))
        target, velocity_only = (None, False)
        if valid:
            target, velocity_only = guided_position_target(
                fields, self.local_origin_enu_m, obs.position_enu_m, obs.yaw_enu_rad)
        used = self.autopilot.on_position_target(now_s, obs, target, velocity_only)
        self._count_target(target is not None, used, "global position target")

    def _team_enu_of_global(self, msg: Any) -> np.ndarray | None:
        """Team-frame ENU of a SET_POSITION_TARGET_GLOBAL_INT position; None if invalid."""
        lat, lon, alt = msg.lat_int * 1e-7, msg.lon_int * 1e-7, float(msg.alt)
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0 and math.isfinite(alt)):
            return None
        if msg.coordinate_frame in GLOBAL_AMSL_FRAMES:
            amsl = alt
        elif msg.coordinate_frame in GLOBAL_RELATIVE_FRAMES:
            amsl = self.telemetry.origin_lla[2] + self.autopilot.home_enu_m[2] + alt
        else:
            return None  # terrain frames: no terrain data
        return geodesy.geodetic_to_enu(np.array(lat), np.array(lon), np.array(amsl),
                                       *self.telemetry.origin_lla)

    def _count_target(self, valid: bool, used: bool, what: str) -> None:
        mode = self.autopilot.mode.name
        by_mode = self.counters.setpoints_by_mode
        by_mode[mode] = by_mode.get(mode, 0) + 1
        if not valid:
            self.counters.setpoints_rejected += 1
            self.counters.last_reject_reason = f"{what} not valid (ArduCopter)"
        elif used:
            self.setpoints_taken += 1
        else:
            self.counters.setpoints_ignored += 1

