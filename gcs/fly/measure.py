"""Telemetry as received -> the law's team measurement, the staleness rule, setpoint scaling. Pure.

Frames: world ENU, body FLU, SI units (gcs.link.VehicleState already converted from NED/FRD).

The staleness rule (docs/gcs.md), applied every tick to the data each vehicle would receive:

* A vehicle's sample is the latest position (LOCAL_POSITION_NED), attitude (ATTITUDE_QUATERNION)
  and IMU (HIGHRES_IMU) received on its link, held (zero-order hold) until a newer one arrives.
  Its age is the age of the older of its position and attitude.
* Age <= stale_after_s: fresh; used as is.
* Age > stale_after_s, as a NEIGHBOUR of i: vehicle i drops the edge for this tick (a_ij = 0 in
  row i only), i.e. it flies on its fresh neighbours; counted per (i, tick) as `stale_neighbour`.
* Age > stale_after_s, its OWN data: the row is still computed from the held sample (the law is
  robust to a few missing samples and the vehicle must keep getting setpoints); counted as
  `stale_own`. Beyond link_lost_after_s the mission declares the link lost (gcs.mission).
* A vehicle with no sample yet, or a non-finite one, reuses its last finite sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.control.law import TeamMeasurement


@dataclass(frozen=True, slots=True)
class TeamSample:
    """The team's latest telemetry at one instant, rows in team order (n vehicles).

    position_m, velocity_mps, acceleration_mps2 (n, 3) world ENU; rotation (n, 3, 3) body FLU ->
    world ENU; omega_radps (n, 3) body FLU; age_s (n,) age of the older of position and attitude;
    finite (n,) whether the row came from a complete, finite sample.
    """

    position_m: np.ndarray
    velocity_mps: np.ndarray
    acceleration_mps2: np.ndarray
    rotation: np.ndarray
    omega_radps: np.ndarray
    age_s: np.ndarray
    imu_age_s: np.ndarray
    finite: np.ndarray

    def measurement(self) -> TeamMeasurement:
        return TeamMeasurement(self.position_m, self.velocity_mps, self.acceleration_mps2,
                               self.rotation, self.omega_radps)


def fresh_mask(sample: TeamSample, stale_after_s: float) -> np.ndarray:
    """(n,) True where the vehicle's data is fresh (finite and not older than the bound)."""
    return sample.finite & (sample.age_s <= stale_after_s)


def effective_adjacency(adjacency: np.ndarray, fresh: np.ndarray) -> np.ndarray:
    """Row i keeps a_ij only for fresh neighbours j (the staleness rule); the diagonal is 0."""
    return adjacency * fresh[None, :].astype(float)


def stale_neighbour_counts(adjacency: np.ndarray, fresh: np.ndarray) -> np.ndarray:
    """(n,) how many of each vehicle's graph neighbours are stale this tick."""
    return ((adjacency != 0.0) & ~fresh[None, :]).sum(axis=1)


def torque_max_nm(arm_length_m: np.ndarray, anti_torque_m: np.ndarray,
                  rotor_thrust_max_n: np.ndarray) -> np.ndarray:
    """Torque that a normalised actuator control of 1 asks for, (n, 3) body FLU [N m]:
    (d f_max, d f_max, 2 C f_max), the emulator's (and mixer (51)'s) convention."""
    d, c, f = (np.asarray(x, dtype=float)
               for x in (arm_length_m, anti_torque_m, rotor_thrust_max_n))
    return np.stack((d * f, d * f, 2.0 * c * f), axis=-1)


def normalised_thrust(thrust_n: np.ndarray, max_thrust_n: np.ndarray) -> np.ndarray:
    """Collective thrust T [N] -> MAVLink's 0..1 with each vehicle's max thrust (never its mass).
    Not clipped here: the proxy clamps to 0..1 and counts the clamps."""
    return np.asarray(thrust_n, dtype=float) / np.asarray(max_thrust_n, dtype=float)


def normalised_torque(torque_nm: np.ndarray, torque_max: np.ndarray) -> np.ndarray:
    """Body torque [N m, FLU] -> -1..1 per axis (the proxy clamps and counts)."""
    return np.asarray(torque_nm, dtype=float) / torque_max


def limit_rate_command(rate_cmd_radps: np.ndarray,
                       max_rate_radps: float) -> tuple[np.ndarray, np.ndarray]:
    """Scale each body-rate command (n, 3) down to norm <= max_rate_radps (direction kept).

    Returns (limited, clipped) with clipped (n,) True where a row was scaled. Rationale
    (docs/gcs.md): a rate step the airframe cannot follow saturates the autopilot's mixer, which
    with airmode on trades collective thrust for torque and breaks the thrust the mass
    estimator assumes.
    """
    norm = np.sqrt((rate_cmd_radps * rate_cmd_radps).sum(axis=1))
    scale = np.minimum(1.0, max_rate_radps / np.maximum(norm, 1e-300))
    return rate_cmd_radps * scale[:, None], scale < 1.0


def desaturate_torque(thrust_n: np.ndarray, torque_nm: np.ndarray, arm_length_m: np.ndarray,
                      anti_torque_m: np.ndarray, rotor_thrust_max_n: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Thrust-preserving torque limit of the mixer (51): the largest scaling of (tau_x, tau_y),
    then of tau_z, that the four rotors (each 0..f_max) can produce at collective thrust T.

    With f = c + (p, q, -p, -q) + y (1, -1, 1, -1), c = T/4, p = tau_y/(2d), q = -tau_x/(2d),
    y = tau_z/(4C): roll/pitch need max(|p|, |q|) <= min(c, f_max - c); yaw then gets the
    headroom left. An autopilot that honours the torque first would otherwise change the thrust
    (airmode), which the law (and its I&I mass estimator) does not know. Returns (torque, limited)
    with limited (n,) True where the torque was reduced. (n,) / (n, 3) arrays, body FLU.
    """
    c = np.clip(0.25 * np.asarray(thrust_n, dtype=float), 0.0, rotor_thrust_max_n)
    room = np.minimum(c, rotor_thrust_max_n - c)
    p = torque_nm[:, 1] / (2.0 * arm_length_m)
    q = -torque_nm[:, 0] / (2.0 * arm_length_m)
    spread = np.maximum(np.abs(p), np.abs(q))
    s_rp = np.minimum(1.0, room / np.maximum(spread, 1e-300))
    p, q = p * s_rp, q * s_rp
    y = torque_nm[:, 2] / (4.0 * anti_torque_m)
    # Yaw headroom at this c, p, q: every rotor c +- (p or q) +- y in [0, f_max].
    lo = np.maximum(np.abs(p), np.abs(q))
    y_room = np.maximum(0.0, np.minimum(c - lo, rotor_thrust_max_n - c - lo))
    y_lim = np.clip(y, -y_room, y_room)
    out = np.stack((-2.0 * arm_length_m * q, 2.0 * arm_length_m * p, 4.0 * anti_torque_m * y_lim),
                   axis=1)
    return out, (s_rp < 1.0) | (y_lim != y)
