"""The position-mode baseline's setpoints: each vehicle's slot of the moving formation (pure).

No law runs in `gcs fly --mode position`: vehicle i is sent its slot as a position setpoint and
its autopilot closes every loop on board. With theta_i the formation offsets and v_r(t) the team
file's reference velocity (the one the law tracks, gcs.control.formation.reference_velocity):

    c(0) = mean_i (p_i(0) - theta_i)           the formation centre where the team is at t = 0
    c(t) = c(0) + integral_0^t v_r(s) ds       moved with the reference velocity
    slot_i(t) = c(t) + theta_i,  velocity v_r(t),  acceleration v_r'(t) (feed-forward)

Everything is in the team frame, ENU metres, z up; the composition root turns each slot into the
vehicle's own local NED frame through its frame tie, as it does the go-to-start targets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.control.formation import reference_velocity

#: v_r's arrays as ReferenceVelocity.as_arrays gives them: constant (3,), amplitude (3, K),
#: omega_radps (3, K), phase_rad (3, K)
Reference = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def formation_centre_m(position_enu_m: np.ndarray, offsets_enu_m: np.ndarray) -> np.ndarray:
    """c = mean_i (p_i - theta_i), (3,) [m, ENU], from positions and offsets (n, 3). Raises
    ValueError when a position is not finite (a slot would be NaN)."""
    p = np.asarray(position_enu_m, dtype=float)
    theta = np.asarray(offsets_enu_m, dtype=float)
    if p.shape != theta.shape or p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"formation centre: positions {p.shape} and offsets {theta.shape} must "
                         "both be (n, 3)")
    if not np.isfinite(p).all():
        bad = sorted({int(i) for i in np.argwhere(~np.isfinite(p))[:, 0]})
        raise ValueError(f"formation centre: the positions of rows {bad} are not finite")
    return (p - theta).mean(axis=0)


def reference_displacement_m(t_s: float, reference: Reference) -> np.ndarray:
    """integral_0^t v_r(s) ds, (3,) [m, ENU], in closed form: per axis constant t + sum
    amplitude / omega (sin(omega t + phase) - sin(phase)) (amplitude cos(phase) t where omega
    is 0, e.g. the zero padding of as_arrays)."""
    constant, amplitude, omega, phase = (np.asarray(a, dtype=float) for a in reference)
    moving = omega != 0.0
    safe = np.where(moving, omega, 1.0)
    terms = np.where(moving, amplitude / safe * (np.sin(omega * t_s + phase) - np.sin(phase)),
                     amplitude * np.cos(phase) * t_s)
    return constant * t_s + terms.sum(axis=1)


@dataclass(frozen=True, slots=True)
class SlotTargets:
    """What every vehicle is sent at one instant, team frame ENU."""

    position_enu_m: np.ndarray  # (n, 3) slot_i = c(t) + theta_i [m]
    velocity_enu_mps: np.ndarray  # (3,) v_r(t), every vehicle's feed-forward [m/s]
    acceleration_enu_mps2: np.ndarray  # (3,) v_r'(t) [m/s^2]


@dataclass(frozen=True, slots=True)
class FormationSlots:
    """The slots of one formation flight: c(0) fixed at its start (`start`), then `at(t)`."""

    centre0_enu_m: np.ndarray  # (3,) c(0) [m]
    offsets_enu_m: np.ndarray  # (n, 3) theta_i [m]
    reference: Reference

    @classmethod
    def start(cls, position_enu_m: np.ndarray, offsets_enu_m: np.ndarray,
              reference: Reference) -> FormationSlots:
        """The formation centred where the team is now (t = 0): c(0) = mean_i (p_i - theta_i)."""
        theta = np.array(offsets_enu_m, dtype=float)
        ref = tuple(np.ascontiguousarray(a, dtype=float) for a in reference)
        return cls(formation_centre_m(position_enu_m, theta), theta, ref)  # type: ignore[arg-type]

    def at(self, t_s: float) -> SlotTargets:
        """Every slot at formation time t_s [s] (t_s = 0: the start)."""
        ref = reference_velocity(float(t_s), *self.reference)  # rows: v_r, v_r', v_r'', v_r'''
        centre = self.centre0_enu_m + reference_displacement_m(t_s, self.reference)
        return SlotTargets(centre + self.offsets_enu_m, ref[0].copy(), ref[1].copy())
