"""`gcs sim`: turn a team config into the compiled closed loop, run it in chunks, return a log."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gcs.config import TORQUE_MODES, ConfigError, ControlMode, TeamConfig
from gcs.config.modes import as_strings
from gcs.config.schema import whole_ratio
from gcs.control.formation import edge_list, reference_velocity
from gcs.control.gains import LawGains
from gcs.control.geometry import rotation_from_rpy
from gcs.control.law import DERIVATIVE_METHODS
from gcs.flightlog import FlightLog, estimates_record
from gcs.sim.loop import (
    LOG_FIELDS,
    MODE_ACTUATORS,
    MODE_RATES,
    N_LOG,
    LawInputs,
    SampledLoop,
    TeamState,
    run_oracle,
    run_sampled,
)

_MODES = {ControlMode.ACTUATORS: MODE_ACTUATORS, ControlMode.RATES: MODE_RATES}
_COL = {name: i for i, name in enumerate(LOG_FIELDS)}


@dataclass(frozen=True, slots=True)
class SimOptions:
    """Overrides of the team file for one run (None: take the file's value).

    oracle: run the verification mode (law inside every RK4 stage, exact derivatives with the
    TRUE masses; for tests and reference figures only, not implementable on a vehicle).
    rate_loop_gain_radps: bandwidth of the idealised autopilot rate loop in `rates` mode.
    """

    law: str | None = None
    mode: str | None = None  # one of SIM_MODES
    derivative: str | None = None
    controller_rate_hz: float | None = None
    plant_rate_hz: float | None = None
    duration_s: float | None = None
    log_rate_hz: float = 100.0
    oracle: bool = False
    rate_loop_gain_radps: float = 50.0


@dataclass(frozen=True, slots=True)
class SimResult:
    log: FlightLog
    min_force_z_n: float
    wall_s: float
    plant_steps: int


class SimulationError(RuntimeError):
    """The closed loop left the law's domain (e.g. a command force admitting no attitude)."""


def law_gains(team: TeamConfig) -> LawGains:
    """The gains the law runs with (the config already holds them as a LawGains record)."""
    return team.controller.gains


def _steps_per(rate_hz: float, plant_hz: float, what: str) -> int:
    steps = whole_ratio(plant_hz, rate_hz)
    if steps is None:
        raise ConfigError(f"{what} {rate_hz} Hz must divide the plant rate {plant_hz} Hz")
    return steps


def simulate(
    team: TeamConfig,
    options: SimOptions = SimOptions(),
    progress: Callable[[float, float], None] | None = None,
) -> SimResult:
    """Fly `team` in-process; `progress(t_s, duration_s)` is called after every simulated second.

    Blocks until done. Raises SimulationError if the command force becomes singular.
    """
    law = options.law or team.controller.law
    mode = options.mode or team.controller.mode
    derivative = options.derivative or team.controller.derivative.method
    if law not in ("adaptive", "baseline"):
        raise ConfigError(f"controller law {law!r}: expected adaptive or baseline")
    if mode == ControlMode.ATTITUDE:
        raise ConfigError(
            "controller mode 'attitude': the vehicle's autopilot closes the attitude loop, which "
            "gcs sim does not model; simulate with --mode rates or actuators, or fly the attitude "
            "mode against vehicle-emu (gcs fly --emulators)")
    if mode not in _MODES:
        raise ConfigError(
            f"controller mode {mode!r}: expected one of {sorted(as_strings(_MODES))}")
    if derivative not in DERIVATIVE_METHODS:
        raise ConfigError(
            f"derivative method {derivative!r}: expected one of {sorted(DERIVATIVE_METHODS)}"
        )
    if options.oracle and mode != ControlMode.ACTUATORS:
        raise ConfigError(
            "the verification (oracle) mode runs the paper's torque law: use mode actuators"
        )
    plant_hz = options.plant_rate_hz or team.sim.plant_rate_hz
    ctrl_hz = options.controller_rate_hz or team.sim.controller_rate_hz
    duration_s = options.duration_s or team.mission.duration_s
    dt_s = 1.0 / plant_hz
    ctrl_every = _steps_per(ctrl_hz, plant_hz, "controller rate")
    log_every = _steps_per(options.log_rate_hz, plant_hz, "log rate")
    n_steps = int(round(duration_s * plant_hz))

    n = team.n
    vehicles = team.vehicles
    mass = team.true_masses_kg().astype(float).copy()
    inertia = np.array([vc.plant.inertia_kgm2 for vc in vehicles], dtype=float)
    p = np.array([vc.initial.position_enu_m for vc in vehicles], dtype=float)
    v = np.array([vc.initial.velocity_enu_mps for vc in vehicles], dtype=float)
    rot = np.array([rotation_from_rpy(*vc.initial.attitude_rpy_rad) for vc in vehicles])
    w = np.array([vc.initial.body_rates_radps for vc in vehicles], dtype=float)
    mhat = np.array([vc.estimates.mhat for vc in vehicles], dtype=float)
    adaptive = law == "adaptive"
    # The baseline flies with known (nominal) parameters: its inertia estimate stays frozen there.
    rhohat = np.array(
        [vc.estimates.inertia_kgm2 if adaptive else vc.baseline_inertia_kgm2 for vc in vehicles],
        dtype=float,
    )
    rhohat0 = rhohat.copy()  # the kernels advance rhohat in place
    nominal = np.array(
        [vc.nominal_mass_kg if vc.nominal_mass_kg is not None else math.nan for vc in vehicles]
    )
    if law == "baseline" and np.isnan(nominal).any():
        raise ConfigError("the baseline law needs nominal_mass_kg on every vehicle")
    graph = edge_list(team.adjacency())  # the law sums over edges (formation.EdgeList)
    offsets = np.ascontiguousarray(team.offsets_enu_m(), dtype=float)
    ref_c, ref_a, ref_w, ref_ph = (
        np.ascontiguousarray(x, dtype=float) for x in team.reference_velocity.as_arrays()
    )
    drop_step = np.full(n, -1, dtype=np.int64)
    drop_factor = np.ones(n)
    for fault in team.faults:
        if getattr(fault, "kind", None) == "mass_drop":
            i = team.index_of(fault.vehicle)
            drop_step[i] = int(round(fault.at_s * plant_hz))
            drop_factor[i] = 1.0 - fault.fraction
    gains = law_gains(team)

    n_log = n_steps // log_every + 1
    log = np.full((n_log, n, N_LOG), np.nan)
    # Before t = 0 the vehicles hover: the accelerometer reads g, so the held thrust is m g.
    thrust_hold = mass * gains.gravity_mps2
    torque_hold = np.zeros((n, 3))
    rate_cmd = np.zeros((n, 3))
    diag = np.zeros((n, 6))
    levant_state = np.zeros((n, 3, 3))
    u_prev = np.zeros((n, 3))
    min_uz = math.inf

    started = time.perf_counter()
    chunk = log_every * max(1, int(plant_hz) // log_every)  # ~1 simulated second per call
    done = 0
    while done < n_steps + 1:
        count = min(chunk, n_steps + 1 - done)
        row0 = done // log_every
        state = TeamState(p, v, rot, w, mass, inertia, drop_step, drop_factor)
        law_in = LawInputs(mhat, rhohat, nominal, graph, offsets, ref_c, ref_a, ref_w, ref_ph,
                           gains, adaptive)
        if options.oracle:
            chunk_min = run_oracle(done, count, dt_s, log_every, state, law_in, log, row0)
            singular = 0
        else:
            sampled = SampledLoop(
                DERIVATIVE_METHODS[derivative], levant_state, u_prev,
                team.controller.derivative.levant_lipschitz,
                team.controller.derivative.levant_substep_s, _MODES[mode],
                options.rate_loop_gain_radps, thrust_hold, torque_hold, rate_cmd, diag)
            chunk_min, singular = run_sampled(
                done, count, dt_s, ctrl_every, log_every, state, law_in, sampled, log, row0)
        min_uz = min(min_uz, chunk_min)
        if singular or not np.isfinite(p).all():
            raise SimulationError(
                f"t = {done * dt_s:.3f}..{(done + count) * dt_s:.3f} s: the command force left the "
                "domain of the command attitude (14) or the state diverged"
            )
        done += count
        if progress is not None:
            progress(min(done, n_steps) * dt_s, duration_s)
    wall_s = time.perf_counter() - started

    t_s = np.arange(n_log) * log_every * dt_s
    ref = np.array([reference_velocity(t, ref_c, ref_a, ref_w, ref_ph)[0] for t in t_s])
    c = _COL
    flight = FlightLog(
        t_s=t_s,
        position_enu_m=log[:, :, c["px"] : c["pz"] + 1],
        velocity_enu_mps=log[:, :, c["vx"] : c["vz"] + 1],
        reference_velocity_enu_mps=ref,
        attitude_error=log[:, :, c["attitude_error"]],
        omega_error_radps=log[:, :, c["omega_error"]],
        mass_estimate_kg=log[:, :, c["mass_estimate"]],
        mass_true_kg=log[:, :, c["mass_true"]],
        inertia_estimate_kgm2=log[:, :, c["jx"] : c["jz"] + 1],
        thrust_n=log[:, :, c["thrust"]],
        force_enu_n=log[:, :, c["ux"] : c["uz"] + 1],
        vehicle_ids=np.array([vc.id for vc in vehicles]),
        sysids=np.array([vc.sysid for vc in vehicles]),
        offsets_enu_m=offsets,
        source="sim",
        controller=law,
        team=team.source_path,
        name=team.name,
        extra={
            "mode": mode,
            "estimates": estimates_record(
                mass_from=["team" if adaptive else "nominal"] * n,
                inertia_from="team" if adaptive else "nominal",
                inertia_kgm2=rhohat0,
                inertia_estimated=adaptive and mode in TORQUE_MODES,
            ),
            "derivative": "exact (oracle)" if options.oracle else derivative,
            "plant_rate_hz": plant_hz,
            "controller_rate_hz": ctrl_hz,
        },
    )
    return SimResult(log=flight, min_force_z_n=float(min_uz), wall_s=wall_s, plant_steps=n_steps)
