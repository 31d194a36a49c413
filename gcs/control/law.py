"""One control tick of the whole team: position stage -> u derivatives -> attitude stage.

`position_stage` and `attitude_stage` are compiled and called by the simulation loop; the
`TeamLaw` class holds the law's own states (mhat, rhohat, differentiator) for a ground station
that runs the law at a fixed tick on measurements (gcs fly). Nothing here reads a clock: time and
the tick length are arguments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from gcs.control.attitude import adaptive_torque, attitude_errors, rate_command, regressor
from gcs.control.derivatives import force_derivatives, levant_advance
from gcs.control.formation import EdgeList, edge_list
from gcs.control.gains import LawGains
from gcs.control.geometry import (
    command_angular_velocity,
    command_attitude,
    is_nonsingular,
    turn_about_thrust_axis,
)
from gcs.control.position import PositionStage, force_law, mass_estimator_rate, thrust

DERIVATIVE_MODEL = 0  #: closed-form u', u'' with v' measured and the law's own mass estimate
DERIVATIVE_LEVANT = 1  #: Levant's differentiator (28) on the sampled u
DERIVATIVE_METHODS = {"model": DERIVATIVE_MODEL, "levant": DERIVATIVE_LEVANT}


@njit(cache=True)
def position_stage(
    position_m,
    velocity_mps,
    rotation,
    mhat,
    nominal_mass_kg,
    graph,
    offsets_m,
    reference_mps,
    gains,
    adaptive,
):
    """Command force u (23), thrust T = |u| (12) and mhat' (24) for the team; `graph` is the
    formation.EdgeList of the weights a_ij.

    Returns a position.PositionStage (u, a, s, ve, phi, kappa, thrust_n, mhat_rate); mhat_rate
    is zero for the baseline.
    """
    u, a, s, ve, ph, kappa = force_law(
        position_m,
        velocity_mps,
        mhat,
        nominal_mass_kg,
        graph,
        offsets_m,
        reference_mps,
        gains,
        adaptive,
    )
    t_n = thrust(u)
    if adaptive:
        mhat_rate = mass_estimator_rate(velocity_mps, rotation, t_n, mhat, ph, gains)
    else:
        mhat_rate = np.zeros_like(mhat)
    return PositionStage(u, a, s, ve, ph, kappa, t_n, mhat_rate)


@njit(cache=True)
def attitude_stage(rotation, omega_radps, force_n, dforce, ddforce, rhohat, gains, adaptive,
                   heading_rad):
    """Command attitude (14) turned by heading_rad (n,) about its thrust axis (zeros: the
    paper's), its rates (docs/control-law.md), torque (26), rhohat' (27), rate command.

    Returns (rc, wc, dwc, tau, rho_rate, omega_cmd, eps, tr_err, we).
    """
    rc = command_attitude(force_n)
    wc, dwc = command_angular_velocity(force_n, dforce, ddforce, rc)
    rc, wc, dwc = turn_about_thrust_axis(rc, wc, dwc, heading_rad)
    re, eps, tr_err, wc_body, we = attitude_errors(rotation, rc, omega_radps, wc)
    gam = regressor(re, omega_radps, wc, dwc, we, wc_body)
    tau, rho_rate = adaptive_torque(eps, tr_err, we, gam, rhohat, gains, adaptive)
    omega_cmd = rate_command(eps, wc_body, gains.k_eps, gains.k_eps_yaw)
    return rc, wc, dwc, tau, rho_rate, omega_cmd, eps, tr_err, we


class TeamMeasurement(NamedTuple):
    """What the law may use at one tick, per vehicle (rows in team order).

    position_m, velocity_mps, acceleration_mps2: world ENU (acceleration = measured specific force
    rotated to world, minus g e3); rotation: body FLU -> world ENU; omega_radps: body FLU. A
    named tuple: the compiled derivatives.force_derivatives takes it whole.
    """

    position_m: np.ndarray
    velocity_mps: np.ndarray
    acceleration_mps2: np.ndarray
    rotation: np.ndarray
    omega_radps: np.ndarray


@dataclass(frozen=True, slots=True)
class TeamCommand:
    """One tick's output for the team: thrust [N], torque [N m, body], body-rate setpoint
    [rad/s, FLU], the command force [N, ENU], and the law's diagnostics."""

    thrust_n: np.ndarray
    torque_nm: np.ndarray
    rate_cmd_radps: np.ndarray
    force_n: np.ndarray
    command_rotation: np.ndarray  # R^c (n, 3, 3), turned by the law's heading
    mass_estimate_kg: np.ndarray
    inertia_estimate_kgm2: np.ndarray
    attitude_error: np.ndarray
    omega_error_radps: np.ndarray


class SingularCommandError(RuntimeError):
    """The command force left the set where the command attitude (14) is defined."""


class TeamLaw:
    """The paper's law for a team, with its adaptive states, advanced one tick at a time.

    Row i of every computation uses only vehicle i's measurement and its graph neighbours'
    (a_ij != 0); the states mhat_i, rhohat_i, and the differentiator of vehicle i are vehicle
    i's own. Estimator states are integrated by forward Euler over the tick (rhohat over at most
    `inertia_step_max_s`).

    `estimate_inertia=False` holds rhohat at rhohat0 for the whole flight: for a flight whose
    setpoint is not the torque (26) (thrust + body rates or attitude, gcs.config.TORQUE_MODES),
    where the update (27) would integrate the errors of a loop the law does not close.

    The weight matrix `adjacency` (n, n) is read once, into `graph` (formation.EdgeList, as
    configured). `step` sums over `active_graph`: the same rows and neighbours with its own
    weight array, which a ground station may change in place between ticks (gcs fly zeroes the
    entries of stale neighbours: gcs.fly.measure.drop_stale_neighbours); a tick then costs
    O(n + m) for m edges and allocates nothing n x n.
    """

    def __init__(
        self,
        gains: LawGains,
        adjacency: np.ndarray,
        offsets_m: np.ndarray,
        mhat0: np.ndarray,
        rhohat0_kgm2: np.ndarray,
        nominal_mass_kg: np.ndarray | None = None,
        adaptive: bool = True,
        derivative: str = "model",
        levant_lipschitz: float = 1e4,
        levant_substep_s: float = 1e-4,
        estimate_inertia: bool = True,
    ) -> None:
        n = adjacency.shape[0]
        if derivative not in DERIVATIVE_METHODS:
            raise ValueError(
                f"derivative method {derivative!r}: expected one of {sorted(DERIVATIVE_METHODS)}"
            )
        self.gains = gains
        self.graph: EdgeList = edge_list(adjacency)
        self.active_graph: EdgeList = self.graph._replace(weight=self.graph.weight.copy())
        self.offsets_m = np.ascontiguousarray(offsets_m, dtype=float)
        self.mhat = np.array(mhat0, dtype=float).reshape(n)
        self.rhohat = np.array(rhohat0_kgm2, dtype=float).reshape(n, 3)
        self.nominal_mass_kg = (
            np.ones(n) if nominal_mass_kg is None else np.asarray(nominal_mass_kg, dtype=float)
        )
        if not adaptive and nominal_mass_kg is None:
            raise ValueError("the baseline law needs nominal masses")
        self.adaptive = adaptive
        self.estimate_inertia = estimate_inertia
        self.derivative = DERIVATIVE_METHODS[derivative]
        self.levant_lipschitz = levant_lipschitz
        self.levant_substep_s = levant_substep_s
        self._levant: np.ndarray | None = None
        self._u_prev: np.ndarray | None = None
        #: per vehicle, the turn of R^c about its thrust axis [rad] (zeros: the paper's (14))
        self.heading_rad = np.zeros(n)
        #: the longest step (27) is advanced by [s] (None: dt_s, whatever it is). A ground station
        #: sets its tick: after ticks it skipped, the one sample it has is the rate error the
        #: vehicle built on a held torque, not the integral of (27) over the gap.
        self.inertia_step_max_s: float | None = None

    def step(
        self, meas: TeamMeasurement, reference_mps: np.ndarray, dt_s: float, adapt: bool = True
    ) -> TeamCommand:
        """Compute the team's command from `meas` at the tick whose v_r derivatives are
        `reference_mps` (4, 3), then advance the adaptive states by `dt_s` seconds.

        adapt=False holds mhat and rhohat (e.g. while the autopilot, not this law, sets the
        thrust: the I&I update (24) assumes the thrust it commands is the one applied); rhohat
        is held in any case without `estimate_inertia`."""
        g = self.gains
        stage = position_stage(
            meas.position_m,
            meas.velocity_mps,
            meas.rotation,
            self.mhat,
            self.nominal_mass_kg,
            self.active_graph,
            self.offsets_m,
            reference_mps,
            g,
            self.adaptive,
        )
        u, kappa, t_n, mhat_rate = stage.force_n, stage.kappa, stage.thrust_n, stage.mhat_rate
        bad = np.flatnonzero(~is_nonsingular(u))
        if bad.size:
            i = int(bad[0])
            raise SingularCommandError(
                f"vehicle index {i}: command force {u[i].tolist()} N admits no command "
                "attitude (14)"
            )
        if self.derivative == DERIVATIVE_LEVANT:
            if self._levant is None:
                self._levant = np.zeros((u.shape[0], 3, 3))
                self._levant[:, :, 0] = u
                self._u_prev = u
            else:
                levant_advance(
                    self._levant,
                    self._u_prev,
                    u,
                    dt_s,
                    self.levant_substep_s,
                    self.levant_lipschitz,
                )
                self._u_prev = u
            du = np.ascontiguousarray(self._levant[:, :, 1])
            ddu = np.ascontiguousarray(self._levant[:, :, 2])
        else:
            du, ddu = force_derivatives(meas, stage, self.mhat, 1.0 / kappa, self.active_graph,
                                        reference_mps, g, self.adaptive)
        rc, wc, dwc, tau, rho_rate, omega_cmd, eps, tr_err, we = attitude_stage(
            meas.rotation, meas.omega_radps, u, du, ddu, self.rhohat, g, self.adaptive,
            self.heading_rad,
        )
        command = TeamCommand(
            thrust_n=t_n,
            torque_nm=tau,
            rate_cmd_radps=omega_cmd,
            force_n=u,
            command_rotation=rc,
            mass_estimate_kg=kappa,
            inertia_estimate_kgm2=self.rhohat.copy(),
            attitude_error=tr_err,
            omega_error_radps=np.sqrt((we * we).sum(axis=1)),
        )
        if adapt:
            self.mhat = self.mhat + dt_s * mhat_rate
            if self.estimate_inertia:
                cap = self.inertia_step_max_s
                self.rhohat = self.rhohat + (dt_s if cap is None else min(dt_s, cap)) * rho_rate
        return command
