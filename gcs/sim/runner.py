"""`gcs sim`: turn a team config into the compiled closed loop, run it in chunks, return a log.

One run is `simulate`. A batch (`simulate_batch`, for `gcs sweep`) flies several teams that share
the law's gains, mode and rates as one team of their disjoint union: the law sums over each
vehicle's own edges only, so every vehicle's numbers are those of its own run, bit for bit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields

import numpy as np

from gcs.config import TORQUE_MODES, ConfigError, ControlMode, TeamConfig
from gcs.config.modes import as_strings
from gcs.config.schema import whole_ratio
from gcs.control.formation import EdgeList, edge_list, reference_velocity_series
from gcs.control.gains import LawGains
from gcs.control.geometry import rotation_from_rpy
from gcs.control.law import DERIVATIVE_METHODS
from gcs.flightlog import FlightLog, estimates_record
from gcs.sim.autopilot import attitude_gains, linear_drag_per_s, onboard_response
from gcs.sim.link import lost_masks, make_link
from gcs.sim.loop import (
    LOG_FIELDS,
    MODE_ACTUATORS,
    MODE_ATTITUDE,
    MODE_RATES,
    N_LOG,
    LawInputs,
    SampledLoop,
    TeamState,
    run_oracle,
    run_sampled,
)
from gcs.sim.noise import DRAWS, NOISE_MODELS, make_noise, noise_draws

_MODES = {ControlMode.ACTUATORS: MODE_ACTUATORS, ControlMode.RATES: MODE_RATES,
          ControlMode.ATTITUDE: MODE_ATTITUDE}
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


@dataclass(frozen=True, slots=True)
class _Loop:
    """What every team of one kernel call shares: the law's kind and gains, the rates."""

    law: str
    mode: str
    derivative: str
    oracle: bool
    rate_loop_gain_radps: float
    levant_lipschitz: float
    levant_substep_s: float
    plant_hz: float
    ctrl_hz: float
    duration_s: float
    log_every: int
    ctrl_every: int
    n_steps: int
    gains: LawGains
    reference: tuple  # reference velocity as arrays (c, a, w, phase)
    predict: bool  # the law reads delayed samples carried forward (fly.predict)
    autopilot: str  # sim.autopilot: the vehicles' own loops
    noise: bool  # the law reads the autopilot's telemetry errors (gcs/sim/noise.py)
    velocity_from_position_s: float  # fly.velocity_from_position_s, with the noise
    acceleration_from_velocity_s: float  # fly.acceleration_from_velocity_s, with the noise

    def same_as(self, other: _Loop) -> bool:
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if f.name == "reference":
                if not all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)):
                    return False
            elif a != b:
                return False
        return True


@dataclass(slots=True)
class _Team:
    """One team's arrays for the kernels (or several teams' concatenated): advanced in place."""

    p: np.ndarray
    v: np.ndarray
    rot: np.ndarray
    w: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    mhat: np.ndarray
    rhohat: np.ndarray
    rhohat0: np.ndarray
    nominal: np.ndarray
    graph: EdgeList
    offsets: np.ndarray
    drop_step: np.ndarray
    drop_factor: np.ndarray
    drag_per_s: np.ndarray  # (n,) the airframes' linear drag [1/s] (gcs.sim.autopilot)
    delay_steps: np.ndarray  # (n,) the link's one-way delay in plant steps
    lost_down: np.ndarray  # (ticks, n) the link's lost samples (gcs.sim.link)
    lost_up: np.ndarray  # (ticks, n) and lost setpoints
    noise_draws: np.ndarray  # (ticks, n, DRAWS[+1]) the telemetry errors' normals, or (1, n, DRAWS)

    @property
    def n(self) -> int:
        return self.p.shape[0]


def _loop_of(team: TeamConfig, options: SimOptions) -> _Loop:
    law = options.law or team.controller.law
    mode = options.mode or team.controller.mode
    derivative = options.derivative or team.controller.derivative.method
    if law not in ("adaptive", "baseline"):
        raise ConfigError(f"controller law {law!r}: expected adaptive or baseline")
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
    return _Loop(
        law=law, mode=mode, derivative=derivative, oracle=options.oracle,
        rate_loop_gain_radps=options.rate_loop_gain_radps,
        levant_lipschitz=team.controller.derivative.levant_lipschitz,
        levant_substep_s=team.controller.derivative.levant_substep_s,
        plant_hz=plant_hz, ctrl_hz=ctrl_hz, duration_s=duration_s,
        log_every=_steps_per(options.log_rate_hz, plant_hz, "log rate"),
        ctrl_every=_steps_per(ctrl_hz, plant_hz, "controller rate"),
        n_steps=int(round(duration_s * plant_hz)),
        gains=law_gains(team),
        reference=tuple(
            np.ascontiguousarray(x, dtype=float) for x in team.reference_velocity.as_arrays()),
        predict=team.fly.predict,
        autopilot=team.sim.autopilot,
        noise=team.sim.telemetry_noise and team.sim.autopilot in NOISE_MODELS,
        velocity_from_position_s=team.fly.velocity_from_position_s,
        acceleration_from_velocity_s=team.fly.acceleration_from_velocity_s,
    )


def _team_of(team: TeamConfig, loop: _Loop) -> _Team:
    n = team.n
    vehicles = team.vehicles
    adaptive = loop.law == "adaptive"
    # The baseline flies with known (nominal) parameters: its inertia estimate stays frozen there.
    rhohat = np.array(
        [vc.estimates.inertia_kgm2 if adaptive else vc.baseline_inertia_kgm2 for vc in vehicles],
        dtype=float,
    )
    nominal = np.array(
        [vc.nominal_mass_kg if vc.nominal_mass_kg is not None else math.nan for vc in vehicles]
    )
    if loop.law == "baseline" and np.isnan(nominal).any():
        raise ConfigError("the baseline law needs nominal_mass_kg on every vehicle")
    drop_step = np.full(n, -1, dtype=np.int64)
    drop_factor = np.ones(n)
    for fault in team.faults:
        if getattr(fault, "kind", None) == "mass_drop":
            i = team.index_of(fault.vehicle)
            drop_step[i] = int(round(fault.at_s * loop.plant_hz))
            drop_factor[i] = 1.0 - fault.fraction
    ticks = loop.n_steps // loop.ctrl_every + 1
    lost_down, lost_up = lost_masks(ticks, n, team.sim.link_loss, team.sim.link_seed)
    draws = (noise_draws(team.sim.link_seed, ticks, n, NOISE_MODELS[loop.autopilot]) if loop.noise
             else np.zeros((1, n, DRAWS)))
    return _Team(
        noise_draws=draws,
        delay_steps=np.full(n, int(round(team.sim.link_delay_s * loop.plant_hz)), dtype=np.int64),
        lost_down=lost_down,
        lost_up=lost_up,
        p=np.array([vc.initial.position_enu_m for vc in vehicles], dtype=float),
        v=np.array([vc.initial.velocity_enu_mps for vc in vehicles], dtype=float),
        rot=np.array([rotation_from_rpy(*vc.initial.attitude_rpy_rad) for vc in vehicles]),
        w=np.array([vc.initial.body_rates_radps for vc in vehicles], dtype=float),
        mass=team.true_masses_kg().astype(float).copy(),
        inertia=np.array([vc.plant.inertia_kgm2 for vc in vehicles], dtype=float),
        mhat=np.array([vc.estimates.mhat for vc in vehicles], dtype=float),
        rhohat=rhohat,
        rhohat0=rhohat.copy(),  # the kernels advance rhohat in place
        nominal=nominal,
        graph=edge_list(team.adjacency()),  # the law sums over edges (formation.EdgeList)
        offsets=np.ascontiguousarray(team.offsets_enu_m(), dtype=float),
        drop_step=drop_step,
        drop_factor=drop_factor,
        drag_per_s=np.full(n, linear_drag_per_s(loop.autopilot)),
    )


def _union(teams: Sequence[_Team]) -> _Team:
    """The teams as one: arrays stacked in order, each graph's indices shifted to its rows."""
    starts, neighbours, weights = [np.zeros(1, dtype=np.int64)], [], []
    first_vehicle = first_edge = 0
    for t in teams:
        g = t.graph
        starts.append(g.row_start[1:] + first_edge)
        neighbours.append(g.neighbour + first_vehicle)
        weights.append(g.weight)
        first_vehicle += t.n
        first_edge += g.neighbour.shape[0]
    stacked = {
        f.name: np.concatenate([getattr(t, f.name) for t in teams],
                               axis=1 if f.name in ("lost_down", "lost_up", "noise_draws")
                               else 0)
        for f in fields(_Team) if f.name != "graph"
    }
    graph = EdgeList(np.ascontiguousarray(np.concatenate(starts)),
                     np.ascontiguousarray(np.concatenate(neighbours), dtype=np.int64),
                     np.ascontiguousarray(np.concatenate(weights)))
    return _Team(graph=graph, **{k: np.ascontiguousarray(a) for k, a in stacked.items()})


def _advance(
    loop: _Loop, team: _Team, progress: Callable[[float, float], None] | None
) -> tuple[np.ndarray, float]:
    """Fly `team` for the whole run; returns the kernel log (rows, n, N_LOG) and min u_z."""
    n, dt_s, log_every = team.n, 1.0 / loop.plant_hz, loop.log_every
    gains = loop.gains
    n_log = loop.n_steps // log_every + 1
    log = np.full((n_log, n, N_LOG), np.nan)
    # Before t = 0 the vehicles hover: the accelerometer reads g, so the held thrust is m g.
    thrust_hold = team.mass * gains.gravity_mps2
    torque_hold = np.zeros((n, 3))
    rate_cmd = np.zeros((n, 3))
    diag = np.zeros((n, 6))
    levant_state = np.zeros((n, 3, 3))
    u_prev = np.zeros((n, 3))
    rc_hold = np.array([r.copy() for r in team.rot])  # hover: the command is the attitude held
    link = make_link(team.delay_steps, team.lost_down, team.lost_up, loop.predict)
    onboard = onboard_response(loop.autopilot, loop.plant_hz, n, thrust_hold)
    attitude_gain = attitude_gains(loop.autopilot)
    noise = make_noise(NOISE_MODELS[loop.autopilot] if loop.noise else None,
                       team.noise_draws.shape[0], n, loop.ctrl_every / loop.plant_hz,
                       team.noise_draws, loop.velocity_from_position_s,
                       loop.acceleration_from_velocity_s)
    min_uz = math.inf
    ref_c, ref_a, ref_w, ref_ph = loop.reference
    chunk = log_every * max(1, int(loop.plant_hz) // log_every)  # ~1 simulated second per call
    done = 0
    while done < loop.n_steps + 1:
        count = min(chunk, loop.n_steps + 1 - done)
        row0 = done // log_every
        state = TeamState(team.p, team.v, team.rot, team.w, team.mass, team.inertia,
                          team.drop_step, team.drop_factor, team.drag_per_s)
        law_in = LawInputs(team.mhat, team.rhohat, team.nominal, team.graph, team.offsets,
                           ref_c, ref_a, ref_w, ref_ph, gains, loop.law == "adaptive")
        if loop.oracle:
            chunk_min = run_oracle(done, count, dt_s, log_every, state, law_in, log, row0)
            singular = 0
        else:
            sampled = SampledLoop(
                DERIVATIVE_METHODS[loop.derivative], levant_state, u_prev,
                loop.levant_lipschitz, loop.levant_substep_s, _MODES[loop.mode],
                loop.rate_loop_gain_radps, thrust_hold, torque_hold, rate_cmd, diag, rc_hold,
                attitude_gain)
            chunk_min, singular = run_sampled(
                done, count, dt_s, loop.ctrl_every, log_every, state, law_in, sampled, link,
                onboard, noise, log, row0)
        min_uz = min(min_uz, chunk_min)
        if singular or not np.isfinite(team.p).all():
            raise SimulationError(
                f"t = {done * dt_s:.3f}..{(done + count) * dt_s:.3f} s: the command force left the "
                "domain of the command attitude (14) or the state diverged"
            )
        done += count
        if progress is not None:
            progress(min(done, loop.n_steps) * dt_s, loop.duration_s)
    return log, min_uz


def _flight_log(team_cfg: TeamConfig, loop: _Loop, arrays: _Team, log: np.ndarray) -> FlightLog:
    dt_s = 1.0 / loop.plant_hz
    t_s = np.arange(log.shape[0]) * loop.log_every * dt_s
    ref = reference_velocity_series(t_s, *loop.reference)
    c = _COL
    n = team_cfg.n
    adaptive = loop.law == "adaptive"
    return FlightLog(
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
        vehicle_ids=np.array([vc.id for vc in team_cfg.vehicles]),
        sysids=np.array([vc.sysid for vc in team_cfg.vehicles]),
        offsets_enu_m=arrays.offsets,
        source="sim",
        controller=loop.law,
        team=team_cfg.source_path,
        name=team_cfg.name,
        extra={
            "mode": loop.mode,
            "estimates": estimates_record(
                mass_from=["team" if adaptive else "nominal"] * n,
                inertia_from="team" if adaptive else "nominal",
                inertia_kgm2=arrays.rhohat0,
                inertia_estimated=adaptive and loop.mode in TORQUE_MODES,
            ),
            "derivative": "exact (oracle)" if loop.oracle else loop.derivative,
            "plant_rate_hz": loop.plant_hz,
            "controller_rate_hz": loop.ctrl_hz,
        },
    )


def simulate(
    team: TeamConfig,
    options: SimOptions = SimOptions(),
    progress: Callable[[float, float], None] | None = None,
) -> SimResult:
    """Fly `team` in-process; `progress(t_s, duration_s)` is called after every simulated second.

    Blocks until done. Raises SimulationError if the command force becomes singular.
    """
    loop = _loop_of(team, options)
    arrays = _team_of(team, loop)
    started = time.perf_counter()
    log, min_uz = _advance(loop, arrays, progress)
    wall_s = time.perf_counter() - started
    return SimResult(log=_flight_log(team, loop, arrays, log), min_force_z_n=float(min_uz),
                     wall_s=wall_s, plant_steps=loop.n_steps)


def can_batch(teams: Sequence[TeamConfig], options: SimOptions = SimOptions()) -> bool:
    """Whether `simulate_batch` can fly these teams in one kernel call (same law, mode, gains,
    rates, duration and reference velocity)."""
    loops = [_loop_of(t, options) for t in teams]
    return all(loops[0].same_as(x) for x in loops[1:])


def simulate_batch(
    teams: Sequence[TeamConfig], options: SimOptions = SimOptions()
) -> list[SimResult | SimulationError]:
    """Fly several teams at once, each result equal to its own `simulate` (see the module's
    docstring). If the batch leaves the law's domain, each team is flown alone, so one run's
    divergence is its own `SimulationError` in the list and the others still fly."""
    if not teams:
        return []
    loops = [_loop_of(t, options) for t in teams]
    if not all(loops[0].same_as(x) for x in loops[1:]):
        raise ValueError("simulate_batch: the teams differ in law, mode, gains, rates or "
                         "reference velocity (can_batch)")
    loop = loops[0]
    parts = [_team_of(t, loop) for t in teams]
    started = time.perf_counter()
    try:
        log, _ = _advance(loop, _union(parts), None)
    except SimulationError:
        return [_alone(t, options) for t in teams]
    wall_s = (time.perf_counter() - started) / len(teams)
    results: list[SimResult | SimulationError] = []
    first = 0
    for cfg, arrays in zip(teams, parts, strict=True):
        own = np.ascontiguousarray(log[:, first : first + arrays.n])
        first += arrays.n
        flight = _flight_log(cfg, loop, arrays, own)
        min_uz = float(np.nanmin(own[:, :, _COL["uz"]]))
        results.append(SimResult(flight, min_uz, wall_s, loop.n_steps))
    return results


def _alone(team: TeamConfig, options: SimOptions) -> SimResult | SimulationError:
    try:
        return simulate(team, options)
    except SimulationError as exc:
        return exc
