"""The payload builders of the telemetry scheduler: each fills the rows of one message type for
the vehicles ``idx`` from the fleet's derived arrays (``self._d``), the plant and the fleet
status. A mixin of ``telemetry.Telemetry`` (its state lives there). Pure."""

from __future__ import annotations

import numpy as np

from vehicle_emulator.mavlink.gnss import fill_gps_raw_int
from vehicle_emulator.physics.geodesy import geodetic_of_ned

_GPS = 0x20  # MAV_SYS_STATUS_SENSOR_GPS: present and enabled once there is a global position
_SENSORS = 0x1 | 0x2 | 0x4 | 0x8 | 0x400 | 0x800 | 0x1000 | 0x8000 | 0x200000
_PREARM_CHECK = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK: health set while arming would pass


class TelemetryPayloads:
    """One builder per message type: ``_<name>(rows, idx, now_s, plant, status)``."""

    __slots__ = ()

    def _heartbeat(self, rows, idx, now_s, plant, status) -> None:
        armed = status.armed[idx]
        rows["custom_mode"] = status.custom_mode[idx]
        rows["type"] = 2  # MAV_TYPE_QUADROTOR
        rows["autopilot"] = status.mav_autopilot[idx]
        rows["base_mode"] = status.base_mode_flags[idx] | np.where(armed, 128, 0).astype(np.uint8)
        rows["system_status"] = status.system_status[idx]
        rows["mavlink_version"] = 3

    def _attitude(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        eul, w = d["eul"][idx], d["w_frd"][idx]
        rows["time_boot_ms"] = d["t_att_ms"][idx]
        rows["roll"], rows["pitch"], rows["yaw"] = eul[:, 0], eul[:, 1], eul[:, 2]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]

    def _attitude_quaternion(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        q, w = d["q"][idx], d["w_frd"][idx]
        rows["time_boot_ms"] = d["t_att_ms"][idx]
        rows["q1"], rows["q2"], rows["q3"], rows["q4"] = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]

    def _local_position(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p, v = d["pos_ned"][idx] - status.origin_ned_m[idx], d["vel_ned"][idx]
        rows["time_boot_ms"] = d["t_pos_ms"][idx]
        rows["x"], rows["y"], rows["z"] = p[:, 0], p[:, 1], p[:, 2]
        rows["vx"], rows["vy"], rows["vz"] = v[:, 0], v[:, 1], v[:, 2]

    def _odometry(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p, v, w = d["pos_ned"][idx] - status.origin_ned_m[idx], d["vel_frd"][idx], d["w_frd"][idx]
        rows["time_usec"] = d["t_pos_us"][idx]
        rows["frame_id"] = 1  # MAV_FRAME_LOCAL_NED
        rows["child_frame_id"] = 12  # MAV_FRAME_BODY_FRD: the twist is in the body frame
        rows["x"], rows["y"], rows["z"] = p[:, 0], p[:, 1], p[:, 2]
        rows["q"] = d["q"][idx]
        rows["vx"], rows["vy"], rows["vz"] = v[:, 0], v[:, 1], v[:, 2]
        rows["rollspeed"], rows["pitchspeed"], rows["yawspeed"] = w[:, 0], w[:, 1], w[:, 2]
        rows["pose_covariance"][:, 0] = np.nan
        rows["velocity_covariance"][:, 0] = np.nan
        rows["quality"] = 100

    def _highres_imu(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        acc, w = d["acc_frd"][idx], d["gimu_frd"][idx]
        rows["time_usec"] = d["t_att_us"][idx]
        rows["xacc"], rows["yacc"], rows["zacc"] = acc[:, 0], acc[:, 1], acc[:, 2]
        rows["xgyro"], rows["ygyro"], rows["zgyro"] = w[:, 0], w[:, 1], w[:, 2]
        z = d["z_up"][idx]
        alt0_m = self.origin_lla[2]
        rows["abs_pressure"] = 1013.25 * (1.0 - 2.25577e-5 * (alt0_m + z)) ** 5.25588
        rows["pressure_alt"] = alt0_m + z
        rows["temperature"] = 25.0
        rows["fields_updated"] = 0x3F | 0x200 | 0x800 | 0x1000

    def _global_position(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        p = d["pos_ned"][idx]
        v = d["vel_ned"][idx]
        lat, lon, alt = geodetic_of_ned(p, self.origin_lla)
        rows["time_boot_ms"] = d["t_pos_ms"][idx]
        rows["lat"] = np.round(lat * 1e7)
        rows["lon"] = np.round(lon * 1e7)
        rows["alt"] = np.round(alt * 1e3)
        rows["relative_alt"] = np.round((status.home_ned_m[idx, 2] - p[:, 2]) * 1e3)
        rows["vx"] = np.round(v[:, 0] * 100)
        rows["vy"] = np.round(v[:, 1] * 100)
        rows["vz"] = np.round(v[:, 2] * 100)
        rows["hdg"] = np.round(np.degrees(d["yaw_ned"][idx]) * 100).astype(np.int64) % 36000

    def _attitude_target(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        w = d["rate_sp_frd"][idx]
        rows["time_boot_ms"] = int(now_s * 1e3)
        rows["q"] = d["q_sp"][idx]
        rows["body_roll_rate"], rows["body_pitch_rate"] = w[:, 0], w[:, 1]
        rows["body_yaw_rate"] = w[:, 2]
        rows["thrust"] = plant.thrust_sp_norm[idx]

    def _extended_sys_state(self, rows, idx, now_s, plant, status) -> None:
        rows["landed_state"] = status.landed_state[idx]
        rows["vtol_state"] = status.vtol_state[idx]

    def _sys_status(self, rows, idx, now_s, plant, status) -> None:
        # PX4 v1.16.0 SIH: the GPS health bit is set from boot, but GPS is present and enabled
        # only once the estimator has a global position (with the pre-arm bit, when armable)
        gps = np.where(status.position_ok[idx], _GPS, 0).astype(np.uint32)
        rows["onboard_control_sensors_present"] = _SENSORS | _PREARM_CHECK | gps
        rows["onboard_control_sensors_enabled"] = _SENSORS | _PREARM_CHECK | gps
        rows["onboard_control_sensors_health"] = _SENSORS | _GPS | np.where(
            status.prearm_ok[idx], _PREARM_CHECK, 0
        ).astype(np.uint32)
        rows["load"] = 200
        rows["voltage_battery"] = np.round(status.battery_voltage_v[idx] * 1e3).astype(np.uint16)
        rows["current_battery"] = np.round(status.battery_current_a[idx] * 100).astype(np.int16)
        rows["battery_remaining"] = np.round(status.battery_remaining[idx] * 100).astype(np.int8)
        rows["errors_comm"] = status.errors_comm[idx]

    def _timesync(self, rows, idx, now_s, plant, status) -> None:
        rows["tc1"] = 0
        rows["ts1"] = int(now_s * 1e9)

    def _home_position(self, rows, idx, now_s, plant, status) -> None:
        home = status.home_ned_m[idx]
        lat, lon, alt = geodetic_of_ned(home, self.origin_lla)
        local = home - status.origin_ned_m[idx]
        rows["latitude"] = np.round(lat * 1e7)
        rows["longitude"] = np.round(lon * 1e7)
        rows["altitude"] = np.round(alt * 1e3)
        rows["x"], rows["y"], rows["z"] = local[:, 0], local[:, 1], local[:, 2]
        rows["q"] = np.array([1.0, 0.0, 0.0, 0.0])
        rows["time_usec"] = int(now_s * 1e6)

    def _gps_raw_int(self, rows, idx, now_s, plant, status) -> None:
        d = self._d
        lat, lon, alt = geodetic_of_ned(d["pos_ned"][idx], self.origin_lla)
        fill_gps_raw_int(rows, d["t_pos_us"][idx], lat, lon, alt, d["vel_ned"][idx])

    def _battery_status(self, rows, idx, now_s, plant, status) -> None:
        rows["current_consumed"] = np.round(plant.charge_used_c[idx] / 3.6).astype(np.int32)
        rows["energy_consumed"] = -1
        rows["temperature"] = 32767
        volts = np.full((idx.size, 10), 65535, dtype=np.uint16)
        volts[:, 0] = np.round(status.battery_voltage_v[idx] * 1e3).astype(np.uint16)
        rows["voltages"] = volts
        rows["current_battery"] = np.round(status.battery_current_a[idx] * 100).astype(np.int16)
        rows["battery_function"] = 1  # MAV_BATTERY_FUNCTION_ALL
        rows["type"] = 1  # MAV_BATTERY_TYPE_LIPO
        rows["battery_remaining"] = np.round(status.battery_remaining[idx] * 100).astype(np.int8)
        rows["charge_state"] = 1  # MAV_BATTERY_CHARGE_STATE_OK
