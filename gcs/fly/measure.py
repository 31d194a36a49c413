"""Telemetry as received -> the law's team measurement, the staleness rule, setpoint scaling. Pure.

Frames: world ENU, body FLU, SI units (gcs.link.VehicleState already converted from NED/FRD).

The staleness rule (docs/gcs.md), applied every tick to the data each vehicle would receive:

* A vehicle's sample is the latest position (LOCAL_POSITION_NED), attitude (ATTITUDE_QUATERNION)
  and IMU (HIGHRES_IMU) received on its link, held (zero-order hold) until a newer one arrives.
  Its age is the time since the older of its position and attitude arrived: how long the link has
  not refreshed it. (Its *delay*, the true age from the vehicle's own stamps, is `delay_s`:
  gcs.link.clock; the mission's delay rule reads that, gcs.mission.safety.)
* Age <= stale_after_s: fresh; used as is.
* Age > stale_after_s, as a NEIGHBOUR of i: vehicle i drops the edge for this tick (a_ij = 0 in
  row i only), i.e. it flies on its fresh neighbours; counted per (i, tick) as `stale_neighbour`.
  Applied to the law's edge list in place (`drop_stale_neighbours`): O(m) per tick for m edges.
* Age > stale_after_s, its OWN data: the row is still computed from the held sample (the law is
  robust to a few missing samples and the vehicle must keep getting setpoints); counted as
  `stale_own`. Beyond link_lost_after_s the mission declares the link lost (gcs.mission).
* A vehicle with no sample yet, or a non-finite one, reuses its last finite sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gcs.control.formation import EdgeList
from gcs.control.gains import GRAVITY_MPS2
from gcs.control.law import TeamMeasurement


@dataclass(frozen=True, slots=True)
class TeamSample:
    """The team's latest telemetry at one instant, rows in team order (n vehicles).

    position_m, velocity_mps, acceleration_mps2 (n, 3) world ENU; rotation (n, 3, 3) body FLU ->
    world ENU; omega_radps (n, 3) body FLU; age_s (n,) time since the older of position and
    attitude was received; imu_age_s likewise for HIGHRES_IMU; finite (n,) whether the row came
    from a complete, finite sample; delay_s (n,) true age of the older of position and attitude:
    now minus when the vehicle took it (its time_boot_ms through gcs.link.clock); transit_s (n,)
    how long after it was taken the later-arriving of the two arrived (the link's delay, what the
    delay rule judges; a silent link leaves it unchanged, the receive age grows instead);
    position_taken_s, attitude_taken_s (n,) when the vehicle took its position and its attitude,
    on the ground station's clock (-inf before the first; gcs.control.predict reads them).
    """

    position_m: np.ndarray
    velocity_mps: np.ndarray
    acceleration_mps2: np.ndarray
    rotation: np.ndarray
    omega_radps: np.ndarray
    age_s: np.ndarray
    imu_age_s: np.ndarray
    finite: np.ndarray
    delay_s: np.ndarray
    transit_s: np.ndarray
    position_taken_s: np.ndarray
    attitude_taken_s: np.ndarray

    def measurement(self) -> TeamMeasurement:
        return TeamMeasurement(self.position_m, self.velocity_mps, self.acceleration_mps2,
                               self.rotation, self.omega_radps)


def fresh_mask(sample: TeamSample, stale_after_s: float) -> np.ndarray:
    """(n,) True where the vehicle's data is fresh (finite and not older than the bound)."""
    return sample.finite & (sample.age_s <= stale_after_s)


@njit(cache=True)
def drop_stale_neighbours(graph: EdgeList, fresh: np.ndarray, weight_out: np.ndarray
                          ) -> np.ndarray:
    """The staleness rule on the edge list: entry (i, j) of `graph` keeps its weight a_ij in
    `weight_out` (2m,) only if neighbour j is fresh, else 0 (row i only: row j keeps a_ji while
    i is fresh). Written in place; `graph` is the configured graph, `weight_out` the weights
    the law reads (TeamLaw.active_graph.weight). Returns (n,) how many of each vehicle's graph
    neighbours are stale this tick."""
    n = graph.row_start.shape[0] - 1
    stale = np.zeros(n, dtype=np.int64)
    for i in range(n):
        for e in range(graph.row_start[i], graph.row_start[i + 1]):
            a = graph.weight[e]
            if fresh[graph.neighbour[e]]:
                weight_out[e] = a
            else:
                weight_out[e] = 0.0
                if a != 0.0:
                    stale[i] += 1
    return stale


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


def limit_rate_command(rate_cmd_radps: np.ndarray, max_rate_radps: float,
                       max_yaw_rate_radps: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Limit each body-rate command (n, 3) [rad/s, FLU]: the roll/pitch part scaled down to
    norm <= max_rate_radps (its direction kept), the yaw rate clipped to +-max_yaw_rate_radps
    on its own, so a yaw command never shrinks the roll/pitch command that tilts the thrust.

    Returns (limited, clipped) with clipped (n,) True where a row was changed. Rationale
    (docs/gcs.md): a rate step the airframe cannot follow saturates the autopilot's mixer, which
    with airmode on trades collective thrust for torque and breaks the thrust the mass
    estimator assumes; yaw authority is the weakest (PX4 SIH: 0.82 of a 1 rad/s step in 0.6 s).
    """
    cmd = np.asarray(rate_cmd_radps, dtype=float)
    xy = np.sqrt(cmd[:, 0] ** 2 + cmd[:, 1] ** 2)
    scale = np.minimum(1.0, max_rate_radps / np.maximum(xy, 1e-300))
    yaw = np.clip(cmd[:, 2], -max_yaw_rate_radps, max_yaw_rate_radps)
    out = np.column_stack([cmd[:, 0] * scale, cmd[:, 1] * scale, yaw])
    return out, (scale < 1.0) | (yaw != cmd[:, 2])


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


def yaw_rad(rotation: np.ndarray) -> np.ndarray:
    """Heading of body FLU -> world ENU rotations (n, 3, 3): the angle of the body x axis's
    horizontal projection from east, counter-clockwise [rad]; 0 for NaN rows."""
    r = np.asarray(rotation, dtype=float)
    out = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    return np.where(np.isfinite(out), out, 0.0)


def level_rotations(rotation: np.ndarray) -> np.ndarray:
    """Level attitudes (n, 3, 3) at the headings of `rotation` (yaw about world z)."""
    yaw = yaw_rad(rotation)
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros((yaw.shape[0], 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    out[:, 2, 2] = 1.0
    return out


def command_heading_rad(heading: str | float, rotation: np.ndarray) -> np.ndarray:
    """The turn of R^c about its thrust axis per vehicle (TeamLaw.heading_rad) for the team
    file's `fly.heading`: "hold" each vehicle's heading now (the formation start), "paper" none
    (eq. (14): heading ~0, east), a number: that compass heading [deg, 0 north, 90 east; ENU yaw
    = 90 deg - heading] for every vehicle. (14)'s own heading is second order in the tilt, so the
    command's heading is the turn to within it (docs/gcs.md)."""
    n = np.asarray(rotation).shape[0]
    if heading == "hold":
        return yaw_rad(rotation)
    if heading == "paper":
        return np.zeros(n)
    if isinstance(heading, int | float) and math.isfinite(heading):
        return np.full(n, math.radians(90.0 - float(heading)))
    raise ValueError(f"fly.heading {heading!r}: expected hold, paper or a number of degrees")


#: `estimates.mhat: from_hover`: the mean over the last HOVER_WINDOW_S of ATTITUDE_TARGET thrust
#: the vehicle reports while it holds, before the formation start (PRIME lasts at least this).
HOVER_WINDOW_S = 2.0
HOVER_MIN_SAMPLES = 10
HOVER_RATE_HZ = 10.0  # ATTITUDE_TARGET asked this often (PX4 streams it at 10 Hz by default)


@dataclass(frozen=True, slots=True)
class HoverEstimate:
    """One vehicle's initial mass estimate from its hover (docs/gcs.md, "Initial mass")."""

    thrust_norm: float  # mean reported thrust, 0..1
    samples: int
    mass_kg: float  # thrust_norm * max_thrust_n / g: the thrust-equivalent mass
    mhat0: float  # phi(0) mass / alpha_m
    least_mhat0: float | None  # Proposition 2's bound (phi(0) - 1) mbar / alpha_m; None: no mbar

    @property
    def proposition2_holds(self) -> bool:
        return self.least_mhat0 is None or self.mhat0 >= self.least_mhat0


class HoverThrust:
    """ATTITUDE_TARGET thrust samples (receive time, thrust) per vehicle, newest last."""

    def __init__(self, n: int) -> None:
        self._t: list[list[float]] = [[] for _ in range(n)]
        self._u: list[list[float]] = [[] for _ in range(n)]

    def add(self, i: int, rx_time_s: float, thrust_norm: float) -> bool:
        """Record one sample (a repeat of the newest, or a non-finite or out-of-range thrust, is
        not recorded); returns whether it was."""
        t = self._t[i]
        if (t and rx_time_s <= t[-1]) or not (math.isfinite(thrust_norm)
                                              and 0.0 < thrust_norm <= 1.0):
            return False
        t.append(rx_time_s)
        self._u[i].append(thrust_norm)
        if len(t) > 4096:  # bounded: keep the newest half
            del t[:2048], self._u[i][:2048]
        return True

    def estimate(self, i: int, now_s: float, max_thrust_n: float, alpha_m: float, phi0: float,
                 mass_bound_kg: float | None,
                 window_s: float = HOVER_WINDOW_S) -> HoverEstimate | None:
        """The estimate from the samples of the last `window_s` before `now_s`; None with fewer
        than HOVER_MIN_SAMPLES of them."""
        t = np.asarray(self._t[i])
        u = np.asarray(self._u[i])
        keep = (t > now_s - window_s) & (t <= now_s)
        if int(keep.sum()) < HOVER_MIN_SAMPLES:
            return None
        thrust = float(u[keep].mean())
        mass = thrust * max_thrust_n / GRAVITY_MPS2
        least = None if mass_bound_kg is None else (phi0 - 1.0) * mass_bound_kg / alpha_m
        return HoverEstimate(thrust, int(keep.sum()), mass, phi0 * mass / alpha_m, least)

