"""The emulated fleet's continuous part: inner loops + mixer + motors + physics + ground, batched.

``FleetPlant`` owns every per-vehicle array (ENU world, FLU body, SI units) and advances the whole
fleet by ``k`` fixed physics steps in one numba call (``_step_kernel``). Per step and vehicle:

1. control mode -> (collective thrust [N], body torque [N m]) through the onboard cascade in
   inner.py (position -> attitude -> rate) or directly (actuator mode, disarmed, idle). The
   nominal personality runs its stiff rate loop every step on the true state; the calibrated ones
   (personality.Dynamics/Sensors, docs/emulator.md "Calibration") sample their IMU model
   (sensors.py) every control period, fly PX4's rate loop or a fitted reference model on the
   measured rates, and hold the output until the next period (optionally one period late);
2. the mixer (51) ``rotors_from_wrench_into`` (rotor limits 0..f_max; MC_AIRMODE decides whether
   thrust or torque gives way at low thrust);
3. optional first-order motor lag, then per-rotor efficiency (fault); angular damping;
4. ``wrench_from_rotors`` -> ``rk4_step`` (physics.py, eqs (6)-(9)), then linear drag (an exact
   decay of the velocity, split from the step);
5. ground plane at z = 0: a vehicle below it is put back on it, level, at rest (landed); the
   vertical speed at touchdown is recorded.

Pure: no clock, no I/O. Time is the step count times ``dt_s``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import IntEnum

import numpy as np
from numba import njit

from flightkit.physics import (
    GRAVITY_MPS2,
    rk4_step,
    rotors_from_wrench_into,
    wrench_from_rotors,
)
from vehicle_emulator.config.personality import Personality, personality_of
from vehicle_emulator.config.team import VehicleSpec
from vehicle_emulator.physics.fleet_arrays import Airframe, Body, Commands, LoopState, Outputs
from vehicle_emulator.physics.inner import attitude_control, position_control, rate_control
from vehicle_emulator.physics.onboard import Onboard, named_params, named_states, onboard_step

__all__ = ["ControlMode", "FleetPlant", "IDLE_THRUST_NORM", "torque_max_nm"]

IDLE_THRUST_NORM = 0.05  # armed on the ground, motors spinning (PX4 MPC_THR_MIN-like)


class ControlMode(IntEnum):
    """What drives a vehicle's rotors (set by the autopilot, read by the kernel)."""

    OFF = 0  # disarmed: rotors stopped
    IDLE = 1  # armed, idle thrust, no torque
    RATES = 2  # body rates (FLU) + normalised thrust
    ATTITUDE = 3  # attitude R_sp (ENU<-FLU) + yaw-rate feed-forward + normalised thrust
    ACTUATOR = 4  # normalised torques (FLU) + normalised thrust
    POSITION = 5  # onboard position/velocity controller (hold, takeoff, land)


def torque_max_nm(arm_length_m: np.ndarray, anti_torque_m: np.ndarray, f_max_n: np.ndarray):
    """Torque scale of normalised actuator controls (n, 3): (d f_max, d f_max, 2 C f_max).

    These are the largest torques the mixer (51) can make about each axis alone.
    """
    return np.stack(
        (arm_length_m * f_max_n, arm_length_m * f_max_n, 2.0 * anti_torque_m * f_max_n), axis=-1
    )


@njit(cache=True)
def _step_kernel(steps, step0, dt, cmd, loops, body, frame, out, cal_par, cal_st):
    """``steps`` physics steps of the fleet from step ``step0``: ``cmd`` (`Commands`), ``loops``
    (`LoopState`), ``body`` (`Body`), ``frame`` (`Airframe`), ``out`` (`Outputs`), the
    personalities' parameters and states (Onboard.plain(): `OnboardParams`, `OnboardStates` as
    plain tuples, named here; onboard.py)."""
    (mode, thrust_cmd, rate_cmd, att_cmd, yaw_rate_ff, torque_cmd, pos_sp, vel_ff, pos_mask,
     yaw_sp, hover) = cmd
    att_sp, rate_sp, thrust_sp, torque_sp, rate_int, omega_prev, vel_int = loops
    pos, vel, rot, omega = body
    mass, inertia, arm, anti, fmax, tmax, motor_tau, airmode, eff = frame
    (rotor_cmd, rotor_f, thrust_n, torque_n, on_ground, impact_speed, touchdowns, sf_body,
     charge_c, t_sp_n) = out
    n = pos.shape[0]
    rotor_eff = np.empty((n, 4))
    cal_par = named_params(cal_par)
    cal_st = named_states(cal_st)
    loop = cal_par.rate_loop
    damping = cal_par.angular_damping_per_s
    drag_decay = cal_par.drag_decay
    drag_k = cal_par.linear_drag_per_s
    thrust_scale = cal_par.thrust_scale
    calibrated = False
    for i in range(n):
        calibrated = calibrated or loop[i] != 0
    for st in range(steps):
        if calibrated:
            onboard_step(step0 + st, dt, cmd, loops, body, on_ground, inertia, tmax, sf_body,
                         cal_par, cal_st)
        for i in range(n):
            m = mode[i]
            landed = on_ground[i]
            t_max = 4.0 * fmax[i]
            if loop[i] != 0:  # calibrated: onboard_step above, holding between its periods
                t_sp_n[i] = thrust_sp[i] * t_max * thrust_scale[i]
                continue
            if m == 0 or m == 1:
                thrust_sp[i] = 0.0 if m == 0 else 0.05
                for k in range(3):
                    torque_sp[i, k] = 0.0
                    rate_int[i, k] = 0.0
                    vel_int[i, k] = 0.0
                    rate_sp[i, k] = 0.0
                    omega_prev[i, k] = omega[i, k]
            elif m == 4:
                thrust_sp[i] = thrust_cmd[i]
                for k in range(3):
                    torque_sp[i, k] = torque_cmd[i, k] * tmax[i, k]
            else:
                if m == 5:
                    thrust_sp[i] = position_control(i, body, cmd, loops, landed, dt)
                    attitude_control(i, rot, att_sp, yaw_rate_ff, rate_sp)
                elif m == 3:
                    thrust_sp[i] = thrust_cmd[i]
                    att_sp[i] = att_cmd[i]
                    attitude_control(i, rot, att_sp, yaw_rate_ff, rate_sp)
                else:  # m == 2
                    thrust_sp[i] = thrust_cmd[i]
                    for k in range(3):
                        rate_sp[i, k] = rate_cmd[i, k]
                rate_control(
                    i, rate_sp, omega, omega_prev, rate_int, inertia, landed, dt, torque_sp
                )
            t_sp_n[i] = thrust_sp[i] * t_max
        # the axes the mixer could not deliver: the calibrated rate loops' anti-windup
        rotors_from_wrench_into(t_sp_n, torque_sp, arm, anti, fmax, rotor_cmd, airmode,
                                cal_st.rate_out.limited)
        for i in range(n):
            tau = motor_tau[i]
            a = 1.0 if tau <= 0.0 else 1.0 - math.exp(-dt / tau)
            for j in range(4):
                rotor_f[i, j] += a * (rotor_cmd[i, j] - rotor_f[i, j])
                rotor_eff[i, j] = rotor_f[i, j] * eff[i, j]
        t_out, tq_out = wrench_from_rotors(rotor_eff, arm, anti)
        for i in range(n):
            thrust_n[i] = t_out[i]
            for k in range(3):
                torque_n[i, k] = tq_out[i, k]
            if loop[i] != 0:  # angular damping (SIH_KDW): -J k w
                for k in range(3):
                    torque_n[i, k] -= inertia[i, k] * damping[i, k] * omega[i, k]
            if mode[i] != 0:
                charge_c[i] += (0.5 + 0.8 * t_out[i]) * dt
        rk4_step(pos, vel, rot, omega, thrust_n, torque_n, mass, inertia, dt)
        for i in range(n):
            if drag_k[i] > 0.0:  # linear drag -m k v: exact decay over the step
                for k in range(3):
                    vel[i, k] *= drag_decay[i]
            r = rot[i]
            if pos[i, 2] <= 0.0:
                if not on_ground[i]:
                    hit = max(-vel[i, 2], 0.0)
                    impact_speed[i] = hit
                    touchdowns[i] += 1
                on_ground[i] = True
                yaw = math.atan2(r[1, 0], r[0, 0])
                c, s = math.cos(yaw), math.sin(yaw)
                r[0, 0], r[0, 1], r[0, 2] = c, -s, 0.0
                r[1, 0], r[1, 1], r[1, 2] = s, c, 0.0
                r[2, 0], r[2, 1], r[2, 2] = 0.0, 0.0, 1.0
                pos[i, 2] = 0.0
                for k in range(3):
                    vel[i, k] = 0.0
                    omega[i, k] = 0.0
                # the ground carries the weight: accelerometer reads +g up (FLU = world here)
                sf_body[i, 0] = 0.0
                sf_body[i, 1] = 0.0
                sf_body[i, 2] = GRAVITY_MPS2
            else:
                on_ground[i] = False
                sf_body[i, 0] = 0.0
                sf_body[i, 1] = 0.0
                sf_body[i, 2] = thrust_n[i] / mass[i]
                if drag_k[i] > 0.0:  # the accelerometer feels the drag: R^T (-k v)
                    kd = drag_k[i]
                    for k in range(3):
                        sf_body[i, k] -= kd * (
                            r[0, k] * vel[i, 0] + r[1, k] * vel[i, 1] + r[2, k] * vel[i, 2]
                        )


def _motor_tau(spec: VehicleSpec, personality_tau_s: float | None) -> float:
    """Motor time constant: the team file's, else the personality's, else none."""
    if spec.motor_time_constant_s is not None:
        return spec.motor_time_constant_s
    return 0.0 if personality_tau_s is None else personality_tau_s


class FleetPlant:
    """State, setpoint and parameter arrays of n vehicles, advanced together by ``step``."""

    def __init__(
        self,
        specs: Sequence[VehicleSpec],
        dt_s: float = 1e-3,
        personalities: Sequence[Personality] | None = None,
    ) -> None:
        if dt_s <= 0.0 or not math.isfinite(dt_s):
            raise ValueError(f"physics step dt_s must be > 0, got {dt_s}")
        n = len(specs)
        self.n = n
        self.dt_s = float(dt_s)
        self.steps_done = 0
        f = np.float64
        # plant
        self.position_enu_m = np.array([s.position_enu_m for s in specs], dtype=f).reshape(n, 3)
        self.velocity_enu_mps = np.array([s.velocity_enu_mps for s in specs], dtype=f).reshape(n, 3)
        self.rotation = np.zeros((n, 3, 3))
        for i, s in enumerate(specs):
            c, sn = math.cos(s.yaw_enu_rad), math.sin(s.yaw_enu_rad)
            self.rotation[i] = [[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]]
        self.omega_flu_radps = np.zeros((n, 3))
        self.mass_kg = np.array([s.mass_kg for s in specs], dtype=f)
        self.inertia_kgm2 = np.array([s.inertia_kgm2 for s in specs], dtype=f).reshape(n, 3)
        self.arm_length_m = np.array([s.arm_length_m for s in specs], dtype=f)
        self.anti_torque_m = np.array([s.anti_torque_m for s in specs], dtype=f)
        self.rotor_thrust_max_n = np.array([s.rotor_thrust_max_n for s in specs], dtype=f)
        self.torque_max_nm = torque_max_nm(
            self.arm_length_m, self.anti_torque_m, self.rotor_thrust_max_n
        )
        if personalities is None:  # else (tests, fitting) one per spec, overriding spec.autopilot
            personalities = [personality_of(s.autopilot) for s in specs]
        if len(personalities) != n:
            raise ValueError(f"{n} vehicles but {len(personalities)} personalities")
        self.motor_time_constant_s = np.array(
            [_motor_tau(s, p.dynamics.motor_time_constant_s)
             for s, p in zip(specs, personalities, strict=True)],
            dtype=f,
        )
        self.airmode = np.zeros(len(specs), dtype=f)  # MC_AIRMODE, PX4's default 0
        self.rotor_efficiency = np.ones((n, 4))
        self.rotor_cmd_n = np.zeros((n, 4))
        self.rotor_thrust_n = np.zeros((n, 4))
        self.thrust_n = np.zeros(n)
        self.torque_nm = np.zeros((n, 3))
        self.on_ground = self.position_enu_m[:, 2] <= 0.0
        self.position_enu_m[:, 2] = np.maximum(self.position_enu_m[:, 2], 0.0)
        self.impact_speed_mps = np.zeros(n)
        self.touchdowns = np.zeros(n, dtype=np.int64)
        self.specific_force_flu_mps2 = np.zeros((n, 3))
        self.specific_force_flu_mps2[:, 2] = GRAVITY_MPS2
        self.charge_used_c = np.zeros(n)
        # setpoints (written by the autopilot layer)
        self.mode = np.zeros(n, dtype=np.int64)
        self.thrust_cmd_norm = np.zeros(n)
        self.rate_cmd_flu_radps = np.zeros((n, 3))
        self.attitude_cmd = np.tile(np.eye(3), (n, 1, 1))
        self.yaw_rate_ff_radps = np.zeros(n)
        self.torque_cmd_norm = np.zeros((n, 3))
        self.position_sp_enu_m = self.position_enu_m.copy()
        self.velocity_ff_enu_mps = np.zeros((n, 3))
        self.position_mask = np.ones((n, 3))
        self.yaw_sp_enu_rad = np.array([s.yaw_enu_rad for s in specs], dtype=f)
        self.sysid = np.array([s.sysid for s in specs], dtype=np.int64)
        self.onboard = Onboard(personalities, self)
        hover = self.mass_kg * GRAVITY_MPS2 / (
            4.0 * self.rotor_thrust_max_n * self.onboard.thrust_scale
        )
        self.hover_thrust_norm = np.clip(hover, 0.05, 0.95)
        # calibrated vehicles in the air start with their (lagged) motors at hover
        airborne = self.onboard.sensor_model & ~self.on_ground
        self.rotor_thrust_n[airborne] = (self.mass_kg * GRAVITY_MPS2 / 4.0)[airborne, None]
        self.rotor_cmd_n[airborne] = self.rotor_thrust_n[airborne]
        self.onboard.thrust_next_norm[airborne] = self.hover_thrust_norm[airborne]
        # controller internals / outputs (telemetry reads these)
        self.attitude_sp = self.rotation.copy()
        self.rate_sp_flu_radps = np.zeros((n, 3))
        self.thrust_sp_norm = np.zeros(n)
        self.torque_sp_nm = np.zeros((n, 3))
        self.rate_integral = np.zeros((n, 3))
        self.omega_prev = np.zeros((n, 3))
        self.velocity_integral = np.zeros((n, 3))
        self._thrust_sp_n = np.zeros(n)

    def set_noise(self, i: int, on: bool) -> bool:
        """EMU_NOISE for vehicle i: the onboard sensor model's noise (calibrated
        personalities); returns whether telemetry should add its own white noise instead (the
        nominal model)."""
        return self.onboard.set_noise(i, on)

    def seed_noise(self, i: int, seed: int) -> None:
        """EMU_SEED for vehicle i: restart its onboard noise stream from (seed, sysid)."""
        self.onboard.seed_noise(i, seed)

    def sample_time_s(self) -> tuple[np.ndarray, np.ndarray]:
        """Per vehicle, the sample times [s] of the reported attitude/IMU and position
        (calibrated personalities: their last IMU sample; nominal: now)."""
        ob, now = self.onboard, self.time_s
        att = np.where(ob.sensor_model, ob.attitude_sample_step * self.dt_s, now)
        pos = np.where(ob.sensor_model, ob.position_sample_step * self.dt_s, now)
        return att, pos

    @property
    def max_collective_thrust_n(self) -> np.ndarray:
        """4 f_max per vehicle [N]: the thrust that normalised thrust 1.0 asks for."""
        return 4.0 * self.rotor_thrust_max_n

    @property
    def time_s(self) -> float:
        """Simulated time since start (steps done times dt)."""
        return self.steps_done * self.dt_s

    def hold_here(self, i: int) -> None:
        """Vehicle i flies the onboard position controller, holding its current position."""
        self.position_sp_enu_m[i] = self.position_enu_m[i]
        self.velocity_ff_enu_mps[i] = 0.0
        self.position_mask[i] = 1.0
        self.yaw_sp_enu_rad[i] = math.atan2(self.rotation[i, 1, 0], self.rotation[i, 0, 0])
        self.velocity_integral[i] = 0.0
        self.mode[i] = ControlMode.POSITION

    def step(self, steps: int) -> None:
        """Advance every vehicle by ``steps`` physics steps (setpoints held constant)."""
        if steps <= 0:
            return
        self.onboard.schedule_heading(self.time_s, self.on_ground)
        _step_kernel(
            int(steps), self.steps_done, self.dt_s,
            Commands(self.mode, self.thrust_cmd_norm, self.rate_cmd_flu_radps, self.attitude_cmd,
                     self.yaw_rate_ff_radps, self.torque_cmd_norm, self.position_sp_enu_m,
                     self.velocity_ff_enu_mps, self.position_mask, self.yaw_sp_enu_rad,
                     self.hover_thrust_norm),
            LoopState(self.attitude_sp, self.rate_sp_flu_radps, self.thrust_sp_norm,
                      self.torque_sp_nm, self.rate_integral, self.omega_prev,
                      self.velocity_integral),
            Body(self.position_enu_m, self.velocity_enu_mps, self.rotation, self.omega_flu_radps),
            Airframe(self.mass_kg, self.inertia_kgm2, self.arm_length_m, self.anti_torque_m,
                     self.rotor_thrust_max_n, self.torque_max_nm, self.motor_time_constant_s,
                     self.airmode, self.rotor_efficiency),
            Outputs(self.rotor_cmd_n, self.rotor_thrust_n, self.thrust_n, self.torque_nm,
                    self.on_ground, self.impact_speed_mps, self.touchdowns,
                    self.specific_force_flu_mps2, self.charge_used_c, self._thrust_sp_n),
            *self.onboard.plain(),
        )
        self.steps_done += int(steps)
