"""How the ardupilot personality flies in GUIDED: takeoff, landing speeds, the guided angle and
position targets it takes (and their GUID_TIMEOUT), and the vertical-speed loop that turns a
climb rate into thrust.
A mixin of ``ArduCopter`` (its state lives there). Pure."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vehicle_emulator.autopilots.ardupilot.modes import GUIDED_MODES, Mode
from vehicle_emulator.autopilots.demand import (
    AttitudeSetpoint,
    Idle,
    Observation,
    PositionTarget,
    RatesSetpoint,
)

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True, slots=True)
class AngleTarget:
    """A guided attitude target (SET_ATTITUDE_TARGET): rates or attitude (the setpoint's thrust
    field unused when ``use_thrust`` is False), and thrust or climb rate."""

    setpoint: RatesSetpoint | AttitudeSetpoint
    use_thrust: bool
    climb_rate_mps: float = 0.0  # when not use_thrust (up positive)


# Vertical loop (ArduPilot's PSC_POSZ_P 1, PSC_VELZ_P 5 style; integrator for mass changes)
POS_Z_P = 1.0
VEL_Z_P = 5.0
VEL_Z_I = 2.0
VEL_Z_I_LIMIT = 3.0  # m/s^2
LEASH_Z_M = 1.0
TAKEOFF_SPOOL_S = 2.5  # NAV_TAKEOFF -> liftoff (recorded 48.70 -> 51.20 s)
LAND_DETECT_S = 1.6  # touchdown -> land complete (recorded 108.08 -> 109.67 s)
LAND_DISARM_S = 0.5  # land complete -> "Disarming motors" in LAND (recorded 109.67 -> 110.16 s)
MAX_TICK_DT_S = 0.1  # the longest step the vertical loop integrates at one tick
STOPPED_MPS = 0.1  # a braking vehicle holds its position below this horizontal speed
TAKEOFF_DONE_M = 0.1


class CopterFlight:
    """GUIDED flight of ``ArduCopter`` (takeoff, landing, angle targets, climb rates)."""

    __slots__ = ()

    def _pilot_down_mps(self) -> float:
        down = self.params["PILOT_SPEED_DN"] or self.params["PILOT_SPEED_UP"]
        return down * 0.01

    def _land_speed_mps(self, obs: Observation) -> float:
        above_home_m = obs.position_enu_m[2] - self.home_enu_m[2]
        if above_home_m > self.params["LAND_ALT_LOW"] * 0.01:
            return self.params["WPNAV_SPEED_DN"] * 0.01
        return self.params["LAND_SPEED"] * 0.01

    def _land_speed_update(self, obs: Observation) -> None:
        d = self.demand
        speed = self._land_speed_mps(obs)
        if isinstance(d, PositionTarget) and d.velocity_ff_enu_mps[2] != -speed:
            self._set(replace(d, velocity_ff_enu_mps=(0.0, 0.0, -speed)))

    def _takeoff_progress(self, now_s: float, obs: Observation) -> None:
        """Spool-up, then a trapezoidal climb (WPNAV_SPEED_UP, WPNAV_ACCEL_Z) to the altitude,
        flown by the position controller; GUIDED then holds there."""
        t = now_s - self._takeoff_started_s
        if self._taking_off == "spool":
            if t < TAKEOFF_SPOOL_S:
                return
            self._taking_off = "climb"
            self.land_complete = False
            self._landed_since_s = None
            self._takeoff_started_s = now_s
            t = 0.0
        z, v = _trapezoid(self._takeoff_alt_m - self._takeoff_from_m, t,
                          self.params["WPNAV_SPEED_UP"] * 0.01,
                          self.params["WPNAV_ACCEL_Z"] * 0.01)
        x, y = obs.position_enu_m[0], obs.position_enu_m[1]
        if isinstance(self.demand, PositionTarget):
            x, y = self.demand.position_enu_m[0], self.demand.position_enu_m[1]
        self._set(PositionTarget((x, y, self._takeoff_from_m + z), (0.0, 0.0, v),
                                 (1.0, 1.0, 1.0), getattr(self.demand, "yaw_enu_rad",
                                                          obs.yaw_enu_rad)))
        if v == 0.0 and abs(obs.position_enu_m[2] - self._takeoff_alt_m) < TAKEOFF_DONE_M:
            self._taking_off = ""

    def expire(self, now_s: float, obs: Observation) -> None:
        """A guided target's GUID_TIMEOUT, checked when it falls due (``deadline_s``) and not
        only at the next tick: ArduCopter checks it on every main-loop pass (400 Hz), so an
        expired attitude target is not flown, nor echoed in ATTITUDE_TARGET, a tick longer."""
        self.deadline_s = math.inf
        if not self.armed or self._taking_off:
            return
        if self.angle_control and self.mode in GUIDED_MODES:
            if self._fresh(now_s):
                self.deadline_s = self._setpoint_s + self.params["GUID_TIMEOUT"]
            else:
                self._fly_angle(now_s, obs, 0.0)
        elif self._velocity_target_expired(now_s):
            self._stop_guided(obs)
        elif self._velocity_target_s is not None:
            self.deadline_s = self._velocity_target_s + self.params["GUID_TIMEOUT"]

    def _velocity_target_expired(self, now_s: float) -> bool:
        return (self._velocity_target_s is not None
                and now_s - self._velocity_target_s > self.params["GUID_TIMEOUT"])

    def _fly_angle(self, now_s: float, obs: Observation, dt_s: float) -> None:
        """Guided angle control (ArduPilot's angle_control_run): the target while fresh, else
        level + altitude hold; idle on the ground unless thrust or a climb is commanded. ``dt_s``:
        the time the altitude target integrates a climb rate over (the tick period at a tick; 0
        when a setpoint or an expiry only changes what is flown)."""
        sp = self.setpoint if self._fresh(now_s) else None
        if sp is None and not self._expiry_counted:
            self._expiry_counted = True
            self.guided_timeouts += 1
        if self._angle_idles(sp):
            if self.armed and not isinstance(self.demand, Idle):
                self._set(Idle())
            return
        if sp is not None and sp.use_thrust:
            if self.demand is not sp.setpoint:
                self._set(sp.setpoint)
            return
        if sp is not None:
            self._set(self._climb(obs, sp.setpoint, sp.climb_rate_mps, dt_s))
        else:
            self._set(self._level_climb(obs, 0.0, dt_s))

    def _angle_idles(self, sp: AngleTarget | None) -> bool:
        """make_safe_ground_handling: disarmed, not auto-armed, or landed without thrust or a
        climb commanded."""
        lifting = sp is not None and (sp.use_thrust or sp.climb_rate_mps > 0.0)
        return not self.armed or not self.auto_armed or (self.land_complete and not lifting)

    def _fresh(self, now_s: float) -> bool:
        return now_s - self._setpoint_s <= self.params["GUID_TIMEOUT"]

    def _level_climb(self, obs: Observation, climb_mps: float, dt_s: float) -> AttitudeSetpoint:
        """Level attitude with the current heading, thrust from the vertical loop."""
        c, s = math.cos(obs.yaw_enu_rad), math.sin(obs.yaw_enu_rad)
        level = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return self._climb(obs, AttitudeSetpoint(level, 0.0, 0.0), climb_mps, dt_s)

    def _climb(self, obs: Observation, sp: RatesSetpoint | AttitudeSetpoint, climb_mps: float,
               dt_s: float) -> RatesSetpoint | AttitudeSetpoint:
        """``sp`` with the thrust of a climb rate (ArduPilot's set_pos_target_z_from_climb_rate:
        the altitude target integrates the rate, within a leash)."""
        z = obs.position_enu_m[2]
        z_ref = z if self._z_ref_m is None else self._z_ref_m
        z_ref = min(max(z_ref + climb_mps * dt_s, z - LEASH_Z_M), z + LEASH_Z_M)
        self._z_ref_m = z_ref
        err = climb_mps + POS_Z_P * (z_ref - z) - obs.velocity_enu_mps[2]
        self._vz_int = min(max(self._vz_int + VEL_Z_I * err * dt_s, -VEL_Z_I_LIMIT),
                           VEL_Z_I_LIMIT)
        acc = VEL_Z_P * err + self._vz_int
        tilt = max(getattr(obs, "tilt_cos", 1.0), 0.5)
        thrust = self.params["MOT_THST_HOVER"] * (1.0 + acc / GRAVITY_MPS2) / tilt
        thrust = min(max(thrust, 0.05), 1.0)
        return replace(sp, thrust_norm=thrust)

    def on_attitude_target(self, now_s: float, obs: Observation, target: AngleTarget | None
                           ) -> bool:
        """A SET_ATTITUDE_TARGET in a guided mode (None: invalid, which stops a GUIDED vehicle;
        GUIDED_NOGPS keeps flying its last target). Ignored elsewhere. True if used."""
        if self.mode not in GUIDED_MODES:
            return False
        if target is None:
            if self.mode is Mode.GUIDED:
                self._stop_guided(obs)
            return False
        self.setpoint = target
        self._setpoint_s = now_s
        self._expiry_counted = False
        if not self.angle_control:
            self.angle_control = True
            self._z_ref_m = obs.position_enu_m[2]
        self._velocity_target_s = None
        self._taking_off = ""
        self.deadline_s = now_s + self.params["GUID_TIMEOUT"]
        self._fly_angle(now_s, obs, 0.0)
        return True

    def on_position_target(self, now_s: float, obs: Observation, target: PositionTarget | None,
                           velocity_only: bool = False) -> bool:
        """A SET_POSITION_TARGET_* in GUIDED, already in team ENU (None: invalid, stops).
        ``velocity_only`` targets time out after GUID_TIMEOUT. GUIDED_NOGPS and other modes
        ignore them. True if used."""
        if self.mode is not Mode.GUIDED:
            return False
        if target is None:
            self._stop_guided(obs)
            return False
        self.angle_control = False
        self._taking_off = ""
        self._velocity_target_s = now_s if velocity_only else None
        if velocity_only:
            self.deadline_s = now_s + self.params["GUID_TIMEOUT"]
        if self._grounded():
            return True  # taken, but a landed vehicle waits for a takeoff (ArduPilot)
        self._braking = False
        self._set(target)
        return True


def _trapezoid(distance_m: float, t_s: float, v_max: float, a_max: float) -> tuple[float, float]:
    """(distance covered, speed) at ``t_s`` of a rest-to-rest move with speed and acceleration
    limits (the speed is 0 once it has arrived)."""
    d = max(distance_m, 0.0)
    v_peak = min(v_max, math.sqrt(a_max * d))
    t_acc = v_peak / a_max
    d_acc = 0.5 * a_max * t_acc * t_acc
    t_cruise = (d - 2.0 * d_acc) / v_peak if v_peak > 0 else 0.0
    t_end = 2.0 * t_acc + t_cruise
    if t_s <= 0.0:
        return 0.0, 0.0
    if t_s < t_acc:
        return 0.5 * a_max * t_s * t_s, a_max * t_s
    if t_s < t_acc + t_cruise:
        return d_acc + v_peak * (t_s - t_acc), v_peak
    if t_s < t_end:
        r = t_end - t_s
        return d - 0.5 * a_max * r * r, a_max * r
    return d, 0.0
